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

use rpkm_transport::Backend;

pub use report::Tally;
pub use validate::{InputLimits, Reject, RejectKind, Validator};

use super::context::{bad_param, CommonArgs, NodeContext};
use super::declare::{keys, served, ParamBound, ParamDefault, ParamSpec};
use super::joint_input::{self, JointConfig};
use super::live;
use super::params::NodeParams;
use super::params::DURATION_S;
use super::shutdown;
use crate::error::bad_input;
use output::Output;

/// `setup` of the TcpMeasurement (instrument NONE) that ends a campaign: the calibrator runs
/// when it receives one. Any publisher may send it to request a calibration.
pub const END_OF_CAMPAIGN: &str = "__end_of_campaign__";

/// Parameter `source` (the option `--source` wins over it).
const SOURCE: ParamSpec = ParamSpec::fixed(
    "source",
    ParamDefault::Str("dds"),
    "dds, joint_states, stdin or a campaign CSV file",
);
/// Parameter `rate_hz`: 1 mHz to 1 MHz, the period 1/rate becomes a `Duration`, which a
/// rate of 1e-300 Hz would overflow.
const RATE: ParamSpec = ParamSpec::fixed(
    "rate_hz",
    ParamDefault::F64(1000.0),
    "pace of a campaign file",
)
.unit("Hz")
.bound(ParamBound::Within(1e-3, 1e6));
/// Parameter `start_delay_s`.
const START_DELAY: ParamSpec = ParamSpec::fixed(
    "start_delay_s",
    ParamDefault::F64(1.0),
    "wait before the first sample",
)
.unit("s")
.bound(ParamBound::Within(DURATION_S.0, DURATION_S.1));
/// Parameter `end_marker`.
const END_MARKER: ParamSpec = ParamSpec::fixed(
    "end_marker",
    ParamDefault::Bool(true),
    "send the end-of-campaign marker at the end of the input",
);
/// Parameter `exit_at_end`.
const EXIT_AT_END: ParamSpec = ParamSpec::fixed(
    "exit_at_end",
    ParamDefault::Bool(false),
    "exit at the end of the input",
);
/// Parameter `views` of the node.
const VIEWS: ParamSpec = ParamSpec {
    description: "publish /joint_states (JointState) on DDS",
    ..super::views::VIEWS
};
/// Parameter `view_every` of the node.
const VIEW_EVERY: ParamSpec = ParamSpec {
    description: "publish the joint states of every N-th accepted state",
    ..super::views::VIEW_EVERY_PARAM
};

/// The node's own parameters: the validation limits and `view_every` live (the next sample
/// is judged by them); the source, pacing and topics need a restart.
pub const PARAMS: [ParamSpec; 13] = [
    SOURCE,
    RATE,
    START_DELAY,
    END_MARKER,
    EXIT_AT_END,
    validate::POSITION_MIN,
    validate::POSITION_MAX,
    validate::FORCE_MAX,
    validate::MEASUREMENT_MAX,
    dds::ACTUATOR_TOPIC_PARAM,
    dds::MEASUREMENT_TOPIC_PARAM,
    VIEWS,
    VIEW_EVERY,
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

/// Where the node's samples come from (option `--source`, else parameter `source`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum IngestSource {
    /// `dds`: a controller's ActuatorState and TcpMeasurement over DDS.
    Dds,
    /// `joint_states`: ros2_control's JointState and the cell's thermometers, on DDS.
    JointStates,
    /// `stdin` (or `-`): a CSV stream in the campaign format.
    Stdin,
    /// Anything else: the path of a campaign CSV file, streamed at `rate_hz`.
    File(String),
}

impl IngestSource {
    /// The source a word names.
    pub fn parse(text: &str) -> Self {
        match text {
            "dds" => Self::Dds,
            "joint_states" => Self::JointStates,
            "stdin" | "-" => Self::Stdin,
            path => Self::File(path.to_owned()),
        }
    }

    /// Whether the source is read over DDS (the node needs a DDS participant for it).
    pub fn is_dds(&self) -> bool {
        matches!(self, Self::Dds | Self::JointStates)
    }
}

impl std::fmt::Display for IngestSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Dds => "dds",
            Self::JointStates => "joint_states",
            Self::Stdin => "stdin",
            Self::File(path) => path,
        })
    }
}

/// What the node reads from its parameters besides the common ones.
struct Settings {
    source: IngestSource,
    limits: InputLimits,
    rate_hz: f64,
    start_delay: Duration,
    end_marker: bool,
    exit_at_end: bool,
    /// The JointState input's settings (source `joint_states`).
    joints: Option<JointConfig>,
}

/// Every parameter key the node declares: its own and the JointState input's (read with
/// source `joint_states` only, accepted with any).
pub fn declared() -> Vec<&'static str> {
    keys(&[&declarations()])
}

/// Every parameter the node declares besides the common ones: its own and the JointState
/// input's.
pub fn declarations() -> Vec<ParamSpec> {
    [PARAMS.as_slice(), &joint_input::PARAMS].concat()
}

/// Opens the node: its source (the option, else parameter `source`, else dds), transport and
/// settings; every bad value is bad input (exit 2) naming the key.
fn open(args: &IngestNodeArgs) -> anyhow::Result<(NodeContext, Settings)> {
    let pre = args
        .common
        .identity("ingest")?
        .params()
        .map_err(bad_param)?;
    let source = IngestSource::parse(&match &args.source {
        Some(s) => s.clone(),
        None => SOURCE.string(&pre).map_err(bad_param)?,
    });
    let extra = source.is_dds().then_some(Backend::Dds);
    let ctx = NodeContext::open("ingest", &args.common, &declared(), extra)?;
    let p = &ctx.params;
    let limits = InputLimits::from_params(p).map_err(bad_param)?;
    let rate_hz = RATE.f64(p).map_err(bad_param)?;
    let start_delay = START_DELAY.f64(p).map_err(bad_param)?;
    // checked whatever the source: a bad value is bad before the cell switches to it
    let joints = JointConfig::from_params(p).map_err(bad_param)?;
    let joints = (source == IngestSource::JointStates).then_some(joints);
    let settings = Settings {
        source,
        limits,
        rate_hz,
        start_delay: Duration::from_secs_f64(start_delay),
        end_marker: END_MARKER.bool(p).map_err(bad_param)?,
        exit_at_end: EXIT_AT_END.bool(p).map_err(bad_param)?,
        joints,
    };
    Ok((ctx, settings))
}

/// What a parameter set changes while the node runs: the limits and `view_every` (and the
/// followers of the `joint_states` source, which it applies itself: checked here).
fn configure(p: &NodeParams) -> anyhow::Result<(InputLimits, u64)> {
    joint_input::followers(p).map_err(bad_param)?;
    let every = VIEW_EVERY.u64(p).map_err(bad_param)?;
    Ok((InputLimits::from_params(p).map_err(bad_param)?, every))
}

/// The node's parameters on its ROS 2 parameter services. `views_default`: whether the views
/// are on unless a file says otherwise.
fn specs(views_default: bool) -> Vec<ParamSpec> {
    let mut specs = served(&[&PARAMS]);
    for s in &mut specs {
        if s.key == VIEWS.key {
            s.default = ParamDefault::Bool(views_default);
        }
    }
    specs
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

/// The start-up line: the source and the output, and with a cell's JointState the joints,
/// the followers (and whether they were kept from the run before a restart) and the
/// thermometers.
fn started_line(ctx: &NodeContext, s: &Settings) -> anyhow::Result<String> {
    let mut line = format!("source {}, publishing on {:?}", s.source, ctx.output);
    if let Some(j) = &s.joints {
        let kept = super::kept::Kept::from_env(ctx.transport.names().namespace(), &ctx.name)
            .map_err(super::context::bad_param)?;
        let at = kept.as_ref().and_then(|k| k.set_at("followers"));
        line = format!("{line}; {}", j.started(at));
    }
    Ok(line)
}

/// Runs the node until its input ends (and `exit_at_end`) or SIGINT/SIGTERM.
pub fn run(args: &IngestNodeArgs) -> anyhow::Result<()> {
    let (mut ctx, s) = open(args)?;
    // The source in use (the option may have chosen it) is the one the services report.
    ctx.params
        .set_from_service(SOURCE.key, serde_yaml::Value::String(s.source.to_string()));
    let views = views(&ctx, &s)?;
    let mut service_specs = specs(views.is_some());
    if s.joints.is_some() {
        service_specs.extend(served(&[&joint_input::PARAMS]));
    }
    let live = live::LiveParams::start(&ctx, &service_specs, |p| configure(p).map(|_| ()))?;
    let source = s.source.to_string();
    let mut out = Output::open((&ctx, &args.common), s.limits, &source, (live, views))?;
    ctx.started(started_line(&ctx, &s)?);
    std::thread::sleep(s.start_delay);
    let ended = match (&s.source, s.joints.clone()) {
        (_, Some(joints)) => joint_states::run(&ctx, &mut out, joints).map(|()| false)?,
        // joint_states always comes with its settings (the arm above)
        (IngestSource::Dds | IngestSource::JointStates, _) => {
            dds::run(&ctx, &mut out).map(|()| false)?
        }
        (IngestSource::Stdin, _) => csv::stream(
            &mut csv::Stdin::spawn(&ctx.name),
            "stdin",
            None,
            &mut out,
            None,
        )?,
        (IngestSource::File(path), _) => file(&mut out, path, s.rate_hz)?,
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
            r#"stdin:6:13 (follower): expected distinct actuator digits 1-4 such as "23", or none (or nothing), found "22""#
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
