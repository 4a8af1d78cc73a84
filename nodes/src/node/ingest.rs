//! `ingest`: the entry of measurements into the node set. Sources:
//! - `dds`: ActuatorState / TcpMeasurement from a controller over DDS (parameters
//!   `input_actuator_topic`, `input_measurement_topic`);
//! - `joint_states`: ros2_control's `sensor_msgs/JointState` and the cell's
//!   `sensor_msgs/Temperature` thermometers, no bridge ([`crate::node::joint_input`],
//!   [`joint_states`]); no measurements;
//! - `stdin`: a CSV stream in the campaign format (header line first), one row per pose;
//! - a campaign CSV file (`rpkm_core::campaign::Campaign`), streamed at `rate_hz`.
//!
//! Every sample is validated before it is republished on `/rpkm/actuator_state` and
//! `/rpkm/tcp_measurement` (SI units, through `crate::campaign_bag` like the bag tools).
//! CSV rows go through the core's campaign reader, the grammar `rpkm calibrate` reads, so a
//! row one rejects the other rejects with the same message ([`csv`]); then every message
//! passes the node's own checks: non-finite numbers, values out of the configured ranges and
//! samples out of order (stamp going back, seq not increasing) ([`validate`]). Rejects are
//! counted per kind, logged, and reported on `/diagnostics` with the last reason
//! ([`report`]). Nothing in the input stops the node. At the end of a file or of stdin an
//! end-of-campaign marker follows (see [`END_OF_CAMPAIGN`]).
//!
//! With `views` on (default with DDS output, except with the `joint_states` source, whose
//! cell publishes `/joint_states` itself) every `view_every`-th accepted state is also
//! published as `sensor_msgs/JointState` on `/joint_states` ([`super::views`]).
//!
//! A managed node like the others ([`super::lifecycle`]): started `--unconfigured` it
//! publishes nothing until configured and activated; while not active a file or stdin source
//! holds its place (streaming goes on at activation) and a live (dds) source's samples are
//! taken and counted (`dropped_inactive`), not published; configure reads the parameters
//! again (limits, `view_every`).
//!
//! The flow: a source ([`dds`], or [`csv::Stdin`] / [`csv::FileLines`]) → one validation
//! loop ([`csv::stream`], or the DDS loop) → [`output::Output`] (publish, count, report).

pub mod csv;
mod dds;
mod joint_states;
mod output;
pub mod report;
pub mod validate;

/// The controller's DDS topics ingest reads by default (its `dds` source).
pub use dds::{ACTUATOR_TOPIC as ACTUATOR_INPUT, MEASUREMENT_TOPIC as MEASUREMENT_INPUT};

use std::time::Duration;

use rpkm_transport::dds_params::ParamRange;
use rpkm_transport::Backend;

pub use report::Tally;
pub use validate::{InputLimits, Reject, RejectKind, Validator};

use super::context::{bad_param, CommonArgs, NodeContext};
use super::joint_input::{self, JointConfig};
use super::live::{self, ParamSpec};
use super::params::NodeParams;
use super::params::DURATION_S;
use super::shutdown;
use crate::error::bad_input;
use output::Output;

/// `setup` of the TcpMeasurement (instrument NONE) that ends a campaign: the calibrator runs
/// when it receives one. Any publisher may send it to request a calibration.
pub const END_OF_CAMPAIGN: &str = "__end_of_campaign__";

/// Parameter keys of the node.
pub const KEYS: [&str; 13] = [
    "source",
    "rate_hz",
    "start_delay_s",
    "end_marker",
    "exit_at_end",
    "position_min_m",
    "position_max_m",
    "force_max_n",
    "measurement_max_m",
    "input_actuator_topic",
    "input_measurement_topic",
    "views",
    "view_every",
];

/// `rpkm node ingest`.
#[derive(clap::Args, Debug, Clone)]
pub struct IngestNodeArgs {
    /// Common node options.
    #[command(flatten)]
    pub common: CommonArgs,
    /// `dds` (live from a controller), `joint_states` (ros2_control's JointState and the
    /// cell's thermometers), `stdin` (CSV stream) or a campaign CSV file (default: parameter
    /// `source`, else dds).
    #[arg(long)]
    pub source: Option<String>,
}

/// What the node reads from its parameters besides the common ones.
struct Settings {
    source: String,
    limits: InputLimits,
    rate_hz: f64,
    start_delay: Duration,
    end_marker: bool,
    exit_at_end: bool,
    /// The JointState input's settings (source `joint_states`).
    joints: Option<JointConfig>,
}

/// The source that reads ros2_control's JointState.
const JOINT_STATES: &str = "joint_states";

/// Every parameter key the node declares: its own and the JointState input's (read with
/// source `joint_states` only, accepted with any).
pub fn declared() -> Vec<&'static str> {
    KEYS.iter().chain(&joint_input::KEYS).copied().collect()
}

/// Opens the node: its source (the option, else parameter `source`, else dds), transport and
/// settings; every bad value is bad input (exit 2) naming the key.
fn open(args: &IngestNodeArgs) -> anyhow::Result<(NodeContext, Settings)> {
    let pre = args
        .common
        .identity("ingest")?
        .params()
        .map_err(bad_param)?;
    let source = match &args.source {
        Some(s) => s.clone(),
        None => pre.string("source", "dds").map_err(bad_param)?,
    };
    let extra = matches!(source.as_str(), "dds" | JOINT_STATES).then_some(Backend::Dds);
    let ctx = NodeContext::open("ingest", &args.common, &declared(), extra)?;
    let p = &ctx.params;
    let limits = limits(p)?;
    // 1 mHz to 1 MHz: the period 1/rate becomes a `Duration`, which a rate of 1e-300 Hz
    // would overflow.
    let rate_hz = p
        .f64_in("rate_hz", 1000.0, RATE_HZ, " Hz")
        .map_err(bad_param)?;
    let start_delay = p
        .f64_in("start_delay_s", 1.0, DURATION_S, " s")
        .map_err(bad_param)?;
    // checked whatever the source: a bad value is bad before the cell switches to it
    let joints = JointConfig::from_params(p).map_err(bad_param)?;
    let joints = (source == JOINT_STATES).then_some(joints);
    let settings = Settings {
        source,
        limits,
        rate_hz,
        start_delay: Duration::from_secs_f64(start_delay),
        end_marker: p.bool("end_marker", true).map_err(bad_param)?,
        exit_at_end: p.bool("exit_at_end", false).map_err(bad_param)?,
        joints,
    };
    Ok((ctx, settings))
}

/// Bounds of `rate_hz`, Hz.
const RATE_HZ: (f64, f64) = (1e-3, 1e6);

/// The validation limits of a parameter set (at start-up and for every set on the parameter
/// services): forces and measurements above 0, positions an interval.
fn limits(p: &NodeParams) -> anyhow::Result<InputLimits> {
    let d = InputLimits::default();
    let (position_min_m, position_max_m) = p
        .interval(
            ("position_min_m", d.position_min_m),
            ("position_max_m", d.position_max_m),
        )
        .map_err(bad_param)?;
    let l = InputLimits {
        position_min_m,
        position_max_m,
        force_max_n: p
            .positive("force_max_n", d.force_max_n)
            .map_err(bad_param)?,
        measurement_max_m: p
            .positive("measurement_max_m", d.measurement_max_m)
            .map_err(bad_param)?,
    };
    Ok(l)
}

/// What a parameter set changes while the node runs: the limits and `view_every` (and the
/// followers of the `joint_states` source, which it applies itself: checked here).
fn configure(p: &NodeParams) -> anyhow::Result<(InputLimits, u64)> {
    joint_input::followers(p).map_err(bad_param)?;
    let every = p
        .u64_in(
            "view_every",
            super::views::VIEW_EVERY,
            super::views::VIEW_EVERY_RANGE,
        )
        .map_err(bad_param)?;
    Ok((limits(p)?, every))
}

/// The node's parameters on its ROS 2 parameter services: the validation limits and
/// `view_every` live (the next sample is judged by them); the source, pacing and topics need
/// a restart. `views_default`: whether the views are on unless a file says otherwise.
fn specs(views_default: bool) -> Vec<ParamSpec> {
    use live::Default::{Bool, Str, F64, U64};
    let d = InputLimits::default();
    let fixed_in = |key, default, description, (lo, hi): (f64, f64)| ParamSpec {
        range: ParamRange::Float(lo, hi),
        ..ParamSpec::fixed(key, default, description)
    };
    let limit = |key, default, description| {
        ParamSpec::live(key, F64(default), description, ParamRange::None)
    };
    vec![
        ParamSpec::fixed(
            "source",
            Str("dds"),
            "dds, joint_states, stdin or a campaign CSV file",
        ),
        fixed_in(
            "rate_hz",
            F64(1000.0),
            "pace of a campaign file, Hz",
            RATE_HZ,
        ),
        fixed_in(
            "start_delay_s",
            F64(1.0),
            "wait before the first sample, s",
            DURATION_S,
        ),
        ParamSpec::fixed(
            "end_marker",
            Bool(true),
            "send the end-of-campaign marker at the end of the input",
        ),
        ParamSpec::fixed("exit_at_end", Bool(false), "exit at the end of the input"),
        limit(
            "position_min_m",
            d.position_min_m,
            "lowest accepted drive position, m (below position_max_m)",
        ),
        limit(
            "position_max_m",
            d.position_max_m,
            "highest accepted drive position, m",
        ),
        limit(
            "force_max_n",
            d.force_max_n,
            "largest accepted |drive force|, N (> 0)",
        ),
        limit(
            "measurement_max_m",
            d.measurement_max_m,
            "largest accepted |x|, |y|, |r| of a measurement, m (> 0)",
        ),
        ParamSpec::fixed(
            "input_actuator_topic",
            Str(dds::ACTUATOR_TOPIC),
            "DDS topic of the drive states (source dds)",
        ),
        ParamSpec::fixed(
            "input_measurement_topic",
            Str(dds::MEASUREMENT_TOPIC),
            "DDS topic of the measurements (source dds)",
        ),
        ParamSpec::fixed(
            "views",
            Bool(views_default),
            "publish /joint_states (JointState) on DDS",
        ),
        ParamSpec::live(
            "view_every",
            U64(super::views::VIEW_EVERY),
            "publish the joint states of every N-th accepted state",
            ParamRange::count(super::views::VIEW_EVERY_RANGE),
        ),
    ]
}

/// Streams a campaign file at `rate_hz`; a file that cannot be read is bad input.
fn file(out: &mut Output<'_>, path: &str, rate_hz: f64) -> anyhow::Result<bool> {
    let bytes =
        std::fs::read(path).map_err(|e| bad_input(format!("{path}: cannot read campaign: {e}")))?;
    let comments = csv::FileLines::comments(&bytes, path);
    let mut lines = csv::FileLines::new(&bytes);
    csv::stream(
        &mut lines,
        path,
        Some(&comments),
        out,
        Some(csv::Pacer::new(rate_hz)),
    )
}

/// The JointState view, off by default with the `joint_states` source (the cell publishes
/// `/joint_states` itself); on, it must not go where the source reads.
fn views(ctx: &NodeContext, s: &Settings) -> anyhow::Result<Option<super::views::JointViews>> {
    let default_on = super::views::on_by_default(ctx) && s.joints.is_none();
    let views = super::views::JointViews::open(ctx, default_on)?;
    if let (Some(v), Some(j)) = (&views, &s.joints) {
        if v.topic() == j.topic {
            return Err(bad_input(format!(
                "ingest: views: true publishes on {}, the topic source joint_states reads; \
                 set views false or another joint_states_topic",
                j.topic
            )));
        }
    }
    Ok(views)
}

/// Runs the node until its input ends (and `exit_at_end`) or SIGINT/SIGTERM.
pub fn run(args: &IngestNodeArgs) -> anyhow::Result<()> {
    let (mut ctx, s) = open(args)?;
    // The source in use (the option may have chosen it) is the one the services report.
    ctx.params
        .set_from_service("source", serde_yaml::Value::String(s.source.clone()));
    let views = views(&ctx, &s)?;
    let mut service_specs = specs(views.is_some());
    if s.joints.is_some() {
        service_specs.extend(joint_input::specs());
    }
    let live = live::LiveParams::start(&ctx, &service_specs, |p| configure(p).map(|_| ()))?;
    let mut out = Output::open((&ctx, &args.common), s.limits, &s.source, (live, views))?;
    ctx.log(format!(
        "source {}, publishing on {:?}",
        s.source, ctx.output
    ));
    std::thread::sleep(s.start_delay);
    let ended = match (s.source.as_str(), s.joints.clone()) {
        (_, Some(joints)) => joint_states::run(&ctx, &mut out, joints).map(|()| false)?,
        ("dds", _) => dds::run(&ctx, &mut out).map(|()| false)?,
        ("stdin" | "-", _) => csv::stream(
            &mut csv::Stdin::spawn(&ctx.name),
            "stdin",
            None,
            &mut out,
            None,
        )?,
        (path, _) => file(&mut out, path, s.rate_hz)?,
    };
    if ended {
        ctx.log(format_args!(
            "end of {}: {} states, {} measurements published, {} rejected",
            s.source,
            out.tally.accepted_states,
            out.tally.accepted_measurements,
            out.tally.rejected_total()
        ));
    }
    if ended && s.end_marker && out.wait_active()?.is_some() {
        out.end_marker()?;
    }
    out.report_now()?;
    // Stay up after the end of the input (unless told otherwise): the launch keeps its nodes,
    // and /diagnostics keeps reporting the final counts.
    while !s.exit_at_end && !shutdown::requested() {
        std::thread::sleep(Duration::from_millis(20));
        out.report_if_due()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::csv::{reject_of, FileLines};
    use super::RejectKind;
    use rpkm_core::campaign::CampaignReader;

    /// The rows of `text` as the CSV sources judge them: a pose's line, or the reject.
    fn judge(text: &str) -> Vec<Result<usize, (RejectKind, String)>> {
        let mut reader = CampaignReader::new("stdin");
        let mut out = Vec::new();
        for line in text.lines() {
            match reader.read_line(line.as_bytes()) {
                Ok(Some(pose)) => out.push(Ok(pose.line)),
                Ok(None) => {}
                Err(e) => {
                    let r = reject_of(&e);
                    out.push(Err((r.kind, r.detail)));
                }
            }
        }
        out
    }

    #[test]
    fn rows_are_judged_by_the_campaign_grammar_and_rejects_kept_apart_by_kind() {
        let text = "t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi,temp\n\
                    3,A,none,0,2611,2611,789,789,10,-5,0,0,23,,,,,20.5\n\
                    4,A,none,0,2611,abc,789,789,0,0,0,0,,,,,,20\n\
                    5,A,none,0,2611,NaN,789,789,0,0,0,0,,,,,,20\n\
                    5,A,none,true,2611,2611,789,789,0,0,0,0,,,,,,20\n\
                    5,A,none,0,2611,2611,789,789,0,0,0,0,22,,,,,20\n\
                    5,A,none,0,9000,2611,789,789,0,0,0,0,,,,,,20\n\
                    2,A,none,0,2611,2611,789,789,0,0,0,0,,,,,,20\n\
                    # comment\n\
                    6,A,none,0,2611\n";
        let kinds: Vec<_> = judge(text)
            .into_iter()
            .map(|r| r.map_err(|(k, _)| k))
            .collect();
        assert_eq!(
            kinds,
            [
                Ok(2),
                Err(RejectKind::Malformed),
                Err(RejectKind::NonFinite),
                Err(RejectKind::Malformed),
                Err(RejectKind::Malformed),
                Err(RejectKind::OutOfRange),
                Err(RejectKind::OutOfOrder),
                Err(RejectKind::Malformed)
            ]
        );
        let details: Vec<String> = judge(text)
            .into_iter()
            .filter_map(Result::err)
            .map(|e| e.1)
            .collect();
        assert_eq!(
            details[0],
            r#"stdin:3:6 (q2): expected a number, found "abc""#
        );
        assert_eq!(
            details[2],
            r#"stdin:5:4 (reset): expected 0 or 1, found "true""#
        );
        assert_eq!(
            details[3],
            r#"stdin:6:13 (follower): expected distinct actuator digits 1-4 such as "23", or nothing, found "22""#
        );
    }

    #[test]
    fn file_comments_are_all_known_before_the_first_pose() {
        let bytes = "\u{feff}# one\nt,setup\n#  two, with a comma\n1,2\n".as_bytes();
        assert_eq!(
            FileLines::comments(bytes, "f.csv"),
            ["one", " two, with a comma"]
        );
    }
}
