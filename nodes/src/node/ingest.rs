//! `ingest`: the entry of measurements into the node set. Sources:
//! - `dds`: ActuatorState / TcpMeasurement from a controller over DDS (parameters
//!   `input_actuator_topic`, `input_measurement_topic`);
//! - `stdin`: a CSV stream in the campaign format (header line first), one row per pose;
//! - a campaign CSV file (`rpkm_core::campaign::Campaign`), streamed at `rate_hz`.
//!
//! Every sample is validated before it is republished on `/rpkm/actuator_state` and
//! `/rpkm/tcp_measurement` (SI units, through `crate::campaign_bag` like the bag tools):
//! malformed rows, non-finite numbers, values out of the configured ranges and samples out of
//! order (stamp going back, seq not increasing) are rejected, counted per kind and reported
//! on `/diagnostics` with the last reason (file:line for CSV). Nothing in the input stops the
//! node. At the end of a file or of stdin an end-of-campaign marker follows (see
//! [`END_OF_CAMPAIGN`]).

use std::collections::HashMap;
use std::io::BufRead;
use std::path::Path;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use rpkm_core::campaign::{Campaign, Instrument, Pose, REQUIRED_COLUMNS};
use rpkm_msgs::{ActuatorState, DiagnosticStatus, TcpMeasurement, Time};
use rpkm_transport::{topic, Backend, Publisher, Qos, Topic};

use super::{diagnostic_array, status, CommonArgs, Every, NodeContext};
use crate::campaign_bag::{campaign_info, pose_messages};

/// `setup` of the TcpMeasurement (instrument NONE) that ends a campaign: the calibrator runs
/// when it receives one. Any publisher may send it to request a calibration.
pub const END_OF_CAMPAIGN: &str = "__end_of_campaign__";

/// Parameter keys of the node.
pub const KEYS: [&str; 11] = [
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
];

/// `rpkm node ingest`.
#[derive(clap::Args, Debug, Clone)]
pub struct IngestArgs {
    /// Common node options.
    #[command(flatten)]
    pub common: CommonArgs,
    /// `dds` (live from a controller), `stdin` (CSV stream) or a campaign CSV file
    /// (default: parameter `source`, else dds).
    #[arg(long)]
    pub source: Option<String>,
}

/// Why a sample was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RejectKind {
    /// Not a row of the campaign format (wrong field count, not a number, unknown name).
    Malformed,
    /// NaN or infinity where a number is required.
    NonFinite,
    /// Outside the configured ranges.
    OutOfRange,
    /// Stamp earlier than the last accepted one, or seq not increasing.
    OutOfOrder,
}

impl RejectKind {
    const ALL: [RejectKind; 4] = [
        Self::Malformed,
        Self::NonFinite,
        Self::OutOfRange,
        Self::OutOfOrder,
    ];
    /// The key on /diagnostics.
    pub fn key(self) -> &'static str {
        match self {
            Self::Malformed => "rejected_malformed",
            Self::NonFinite => "rejected_non_finite",
            Self::OutOfRange => "rejected_out_of_range",
            Self::OutOfOrder => "rejected_out_of_order",
        }
    }
}

/// A rejected sample: kind and a message naming where and what.
#[derive(Debug, Clone, PartialEq)]
pub struct Reject {
    /// Kind.
    pub kind: RejectKind,
    /// What was wrong.
    pub detail: String,
}

fn reject(kind: RejectKind, detail: String) -> Reject {
    Reject { kind, detail }
}

/// Accepted ranges (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Actuator positions, m.
    pub position_min_m: f64,
    /// Actuator positions, m.
    pub position_max_m: f64,
    /// |drive force|, N.
    pub force_max_n: f64,
    /// |x|, |y|, |r| of a measurement, m.
    pub measurement_max_m: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            position_min_m: -0.5,
            position_max_m: 4.5,
            force_max_n: 5.0 * rpkm_core::elastic::NOMINAL_DRIVE_FORCE_N,
            measurement_max_m: 5.0,
        }
    }
}

/// Checks every sample and remembers the last accepted stamps and seq.
#[derive(Debug, Clone, Default)]
pub struct Validator {
    limits: Limits,
    last_state: Option<(Time, u64)>,
    last_measurement: Option<Time>,
}

impl Validator {
    /// A validator with `limits`.
    pub fn new(limits: Limits) -> Self {
        Self {
            limits,
            ..Default::default()
        }
    }

    /// Accepts or rejects a drive state; `label` names its source in the reason.
    pub fn state(&mut self, s: &ActuatorState, label: &str) -> Result<(), Reject> {
        let l = &self.limits;
        for i in 0..4 {
            let (q, f) = (s.position[i], s.force[i]);
            if !q.is_finite() || !f.is_finite() {
                return Err(reject(
                    RejectKind::NonFinite,
                    format!("{label}: seq {}: q{} = {q}, f{} = {f}", s.seq, i + 1, i + 1),
                ));
            }
            if !(l.position_min_m..=l.position_max_m).contains(&q) {
                return Err(reject(
                    RejectKind::OutOfRange,
                    format!(
                        "{label}: seq {}: q{} = {q} m outside [{}, {}] m",
                        s.seq,
                        i + 1,
                        l.position_min_m,
                        l.position_max_m
                    ),
                ));
            }
            if f.abs() > l.force_max_n {
                return Err(reject(
                    RejectKind::OutOfRange,
                    format!(
                        "{label}: seq {}: |f{}| = {} N above {} N",
                        s.seq,
                        i + 1,
                        f.abs(),
                        l.force_max_n
                    ),
                ));
            }
        }
        if usize::from(s.covariate_count) > s.covariates.len() {
            return Err(reject(
                RejectKind::OutOfRange,
                format!(
                    "{label}: seq {}: covariate_count {} above {}",
                    s.seq,
                    s.covariate_count,
                    s.covariates.len()
                ),
            ));
        }
        // NaN marks a covariate not measured at this pose (campaign_bag); infinities are wrong.
        if let Some(c) = s.covariates().iter().find(|c| c.is_infinite()) {
            return Err(reject(
                RejectKind::NonFinite,
                format!("{label}: seq {}: covariate {c}", s.seq),
            ));
        }
        if let Some((stamp, seq)) = self.last_state {
            if s.stamp < stamp || s.seq <= seq {
                return Err(reject(
                    RejectKind::OutOfOrder,
                    format!(
                        "{label}: seq {} stamp {}.{:09} after seq {seq} stamp {}.{:09}",
                        s.seq, s.stamp.sec, s.stamp.nanosec, stamp.sec, stamp.nanosec
                    ),
                ));
            }
        }
        self.last_state = Some((s.stamp, s.seq));
        Ok(())
    }

    /// Accepts or rejects a measurement.
    pub fn measurement(&mut self, m: &TcpMeasurement, label: &str) -> Result<(), Reject> {
        if m.instrument > TcpMeasurement::NONE {
            return Err(reject(
                RejectKind::OutOfRange,
                format!("{label}: instrument id {} (expected 0..=8)", m.instrument),
            ));
        }
        let values = [
            ("x", m.x, m.x_valid),
            ("y", m.y, m.y_valid),
            ("r", m.r, m.r_valid),
            ("psi", m.psi, m.psi_valid),
            ("sigma", m.sigma, true),
        ];
        for (name, v, valid) in values {
            if valid && !v.is_finite() {
                return Err(reject(
                    RejectKind::NonFinite,
                    format!("{label}: setup {:?}: {name} = {v}", m.setup),
                ));
            }
        }
        for (name, v, valid) in &values[..3] {
            if *valid && v.abs() > self.limits.measurement_max_m {
                return Err(reject(
                    RejectKind::OutOfRange,
                    format!(
                        "{label}: setup {:?}: |{name}| = {} m above {} m",
                        m.setup,
                        v.abs(),
                        self.limits.measurement_max_m
                    ),
                ));
            }
        }
        if m.sigma < 0.0 {
            return Err(reject(
                RejectKind::OutOfRange,
                format!("{label}: setup {:?}: sigma {} < 0", m.setup, m.sigma),
            ));
        }
        if let Some(stamp) = self.last_measurement {
            if m.stamp < stamp {
                return Err(reject(
                    RejectKind::OutOfOrder,
                    format!(
                        "{label}: measurement stamp {}.{:09} before {}.{:09}",
                        m.stamp.sec, m.stamp.nanosec, stamp.sec, stamp.nanosec
                    ),
                ));
            }
        }
        self.last_measurement = Some(m.stamp);
        Ok(())
    }
}

/// Accepted and rejected counts.
#[derive(Debug, Clone, Default)]
pub struct Tally {
    /// ActuatorStates published.
    pub accepted_states: u64,
    /// TcpMeasurements published.
    pub accepted_measurements: u64,
    /// Rejects per kind.
    pub rejected: HashMap<RejectKind, u64>,
    /// The last reject's reason.
    pub last_reject: Option<String>,
    rejected_at_last_report: u64,
}

impl Tally {
    /// Counts a reject.
    pub fn reject(&mut self, r: Reject) {
        *self.rejected.entry(r.kind).or_default() += 1;
        self.last_reject = Some(r.detail);
    }

    /// All rejects.
    pub fn rejected_total(&self) -> u64 {
        self.rejected.values().sum()
    }

    /// The /diagnostics status: WARN when samples were rejected since the last report.
    pub fn status(&mut self, node: &str, source: &str, note: Option<&str>) -> DiagnosticStatus {
        let total = self.rejected_total();
        let fresh = total - self.rejected_at_last_report;
        self.rejected_at_last_report = total;
        let (level, mut message) = if fresh > 0 {
            (
                DiagnosticStatus::WARN,
                format!(
                    "{fresh} samples rejected since the last report; last: {}",
                    self.last_reject.as_deref().unwrap_or("")
                ),
            )
        } else {
            (
                DiagnosticStatus::OK,
                format!(
                    "{} states, {} measurements accepted",
                    self.accepted_states, self.accepted_measurements
                ),
            )
        };
        if let Some(n) = note {
            message = format!("{message}; {n}");
        }
        let mut values = vec![
            ("source", source.to_owned()),
            ("accepted_states", self.accepted_states.to_string()),
            (
                "accepted_measurements",
                self.accepted_measurements.to_string(),
            ),
            ("rejected_total", total.to_string()),
        ];
        for k in RejectKind::ALL {
            values.push((
                k.key(),
                self.rejected.get(&k).copied().unwrap_or(0).to_string(),
            ));
        }
        values.push(("last_reject", self.last_reject.clone().unwrap_or_default()));
        status(level, node, message, values)
    }
}

/// Field index of each required column, and (field index, name) of the covariates.
type Columns = (HashMap<&'static str, usize>, Vec<(usize, String)>);

/// Reads campaign-format CSV rows one at a time: the row-level rules of the format (number
/// syntax, names, follower spelling); campaign-level rules (resets per setup) need the whole
/// file and are `Campaign::parse`'s.
#[derive(Debug, Clone)]
pub struct CsvRows {
    label: String,
    columns: Option<Columns>,
    field_count: usize,
}

impl CsvRows {
    /// A reader for the source called `label` (file name or `stdin`).
    pub fn new(label: &str) -> Self {
        Self {
            label: label.to_owned(),
            columns: None,
            field_count: 0,
        }
    }

    /// The covariate names of the header (empty before it).
    pub fn covariate_names(&self) -> Vec<String> {
        self.columns
            .as_ref()
            .map(|(_, c)| c.iter().map(|(_, n)| n.clone()).collect())
            .unwrap_or_default()
    }

    /// One line (1-based `line`): `None` for comments, blank lines and the header,
    /// else a pose (mm, as in the file) or the reason it is rejected.
    pub fn line(&mut self, line: usize, text: &str) -> Option<Result<Pose, Reject>> {
        let text = text
            .trim_start_matches('\u{feff}')
            .trim_end_matches(['\r', '\n']);
        if text.trim().is_empty() || text.trim_start().starts_with('#') {
            return None;
        }
        let fields: Vec<&str> = text.split(',').map(str::trim).collect();
        let at = |what: String| format!("{}:{line}: {what}", self.label);
        let Some((cols, covs)) = &self.columns else {
            let mut cols = HashMap::new();
            let mut covs = Vec::new();
            for (i, &name) in fields.iter().enumerate() {
                match REQUIRED_COLUMNS.iter().find(|&&c| c == name) {
                    Some(&c) => {
                        cols.insert(c, i);
                    }
                    None => covs.push((i, name.to_owned())),
                }
            }
            if let Some(missing) = REQUIRED_COLUMNS.iter().find(|c| !cols.contains_key(*c)) {
                return Some(Err(reject(
                    RejectKind::Malformed,
                    at(format!("header misses column {missing}")),
                )));
            }
            self.field_count = fields.len();
            self.columns = Some((cols, covs));
            return None;
        };
        if fields.len() != self.field_count {
            return Some(Err(reject(
                RejectKind::Malformed,
                at(format!(
                    "{} fields, the header has {}",
                    fields.len(),
                    self.field_count
                )),
            )));
        }
        let get = |c: &str| fields[cols[c]];
        let num = |c: &str| -> Result<Option<f64>, Reject> {
            let s = get(c);
            if s.is_empty() {
                return Ok(None);
            }
            let v: f64 = s.parse().map_err(|_| {
                reject(
                    RejectKind::Malformed,
                    at(format!("({c}) expected a number, found {s:?}")),
                )
            })?;
            if !v.is_finite() {
                return Err(reject(
                    RejectKind::NonFinite,
                    at(format!("({c}) {s} is not finite")),
                ));
            }
            Ok(Some(v))
        };
        let req = |c: &str| -> Result<f64, Reject> {
            num(c)?.ok_or_else(|| reject(RejectKind::Malformed, at(format!("({c}) is empty"))))
        };
        let pose = (|| -> Result<Pose, Reject> {
            let instrument: Instrument = get("instrument")
                .parse()
                .map_err(|e| reject(RejectKind::Malformed, at(format!("(instrument) {e}"))))?;
            let reset = match get("reset") {
                "1" | "true" => true,
                "0" | "false" | "" => false,
                other => {
                    return Err(reject(
                        RejectKind::Malformed,
                        at(format!("(reset) expected 0 or 1, found {other:?}")),
                    ))
                }
            };
            let mut follower = [false; 4];
            for ch in get("follower").chars() {
                match ch.to_digit(10) {
                    Some(d @ 1..=4) => follower[d as usize - 1] = true,
                    _ => {
                        return Err(reject(
                            RejectKind::Malformed,
                            at(format!(
                                "(follower) expected digits 1-4, found {:?}",
                                get("follower")
                            )),
                        ))
                    }
                }
            }
            let mut covariates = Vec::with_capacity(covs.len());
            for (i, name) in covs {
                let s = fields[*i];
                covariates.push(if s.is_empty() {
                    None
                } else {
                    let v: f64 = s.parse().map_err(|_| {
                        reject(
                            RejectKind::Malformed,
                            at(format!("({name}) expected a number, found {s:?}")),
                        )
                    })?;
                    if v.is_infinite() || v.is_nan() {
                        return Err(reject(
                            RejectKind::NonFinite,
                            at(format!("({name}) {s} is not finite")),
                        ));
                    }
                    Some(v)
                });
            }
            Ok(Pose {
                t: req("t")?,
                setup: get("setup").to_owned(),
                instrument,
                reset,
                q: [req("q1")?, req("q2")?, req("q3")?, req("q4")?],
                f: [req("f1")?, req("f2")?, req("f3")?, req("f4")?],
                follower,
                x: num("x")?,
                y: num("y")?,
                r: num("r")?,
                psi: num("psi")?,
                covariates,
                line,
            })
        })();
        Some(pose)
    }
}

/// The publishers and bookkeeping shared by the sources.
struct Output {
    states: Publisher<ActuatorState>,
    measurements: Publisher<TcpMeasurement>,
    validator: Validator,
    tally: Tally,
    seq: u64,
    last_stamp: Time,
}

impl Output {
    /// Validates and publishes one pose of a campaign (state, then its measurement).
    fn pose(&mut self, c: &Campaign, pose: &Pose) -> anyhow::Result<()> {
        let label = format!("{}:{}", c.source, pose.line);
        let (mut state, measurement) = match pose_messages(c, self.seq as usize, pose) {
            Ok(m) => m,
            Err(e) => {
                self.tally
                    .reject(reject(RejectKind::OutOfRange, format!("{label}: {e}")));
                return Ok(());
            }
        };
        // seq counts the published states over the node's life, so that it increases across
        // campaigns and the estimates echo a unique number.
        state.seq = self.seq + 1;
        if let Err(r) = self.validator.state(&state, &label) {
            self.tally.reject(r);
            return Ok(());
        }
        if let Err(r) = self.validator.measurement(&measurement, &label) {
            // The state was fine: it still goes out, the measurement does not.
            self.tally.reject(r);
            self.publish_state(&state)?;
            return Ok(());
        }
        self.publish_state(&state)?;
        self.measurements.publish(&measurement)?;
        self.tally.accepted_measurements += 1;
        Ok(())
    }

    fn publish_state(&mut self, state: &ActuatorState) -> anyhow::Result<()> {
        self.states.publish(state)?;
        self.seq = state.seq;
        self.last_stamp = state.stamp;
        self.tally.accepted_states += 1;
        Ok(())
    }

    fn end_marker(&mut self) -> anyhow::Result<()> {
        self.measurements.publish(&TcpMeasurement {
            stamp: self.last_stamp,
            setup: END_OF_CAMPAIGN.to_owned(),
            instrument: TcpMeasurement::NONE,
            ..Default::default()
        })?;
        Ok(())
    }
}

/// An empty campaign carrying a source label and covariate names for `pose_messages`.
fn stub(label: &str, covariate_names: Vec<String>) -> Campaign {
    Campaign {
        source: label.to_owned(),
        covariate_names,
        ..Default::default()
    }
}

/// Runs the node until its input ends (and `exit_at_end`) or SIGINT/SIGTERM.
pub fn run(args: &IngestArgs) -> anyhow::Result<()> {
    let pre = super::NodeParams::load(
        args.common.name.as_deref().unwrap_or("ingest"),
        &args.common.params,
        &args.common.param,
    )
    .map_err(super::bad_param)?;
    let source = match &args.source {
        Some(s) => s.clone(),
        None => pre.string("source", "dds").map_err(super::bad_param)?,
    };
    let extra = (source == "dds").then_some(Backend::Dds);
    let ctx = NodeContext::open("ingest", &args.common, &KEYS, extra)?;
    let p = &ctx.params;
    let bp = super::bad_param;
    let d = Limits::default();
    let limits = Limits {
        position_min_m: p.f64("position_min_m", d.position_min_m).map_err(bp)?,
        position_max_m: p.f64("position_max_m", d.position_max_m).map_err(bp)?,
        force_max_n: p.positive("force_max_n", d.force_max_n).map_err(bp)?,
        measurement_max_m: p
            .positive("measurement_max_m", d.measurement_max_m)
            .map_err(bp)?,
    };
    // 1 mHz to 1 MHz: the period 1/rate becomes a `Duration`, which a rate of 1e-300 Hz
    // would overflow.
    let rate_hz = p
        .f64_in("rate_hz", 1000.0, (1e-3, 1e6), " Hz")
        .map_err(bp)?;
    let start_delay = p
        .f64_in("start_delay_s", 1.0, super::params::DURATION_S, " s")
        .map_err(bp)?;
    let start_delay = Duration::from_secs_f64(start_delay);
    let end_marker = p.bool("end_marker", true).map_err(bp)?;
    let exit_at_end = p.bool("exit_at_end", false).map_err(bp)?;
    let mut out = Output {
        states: ctx.publisher(&topic::ACTUATOR_STATE)?,
        measurements: ctx.publisher(&topic::TCP_MEASUREMENT)?,
        validator: Validator::new(limits),
        tally: Tally::default(),
        seq: 0,
        last_stamp: Time::default(),
    };
    let diagnostics = ctx.publisher(&topic::DIAGNOSTICS)?;
    let info = ctx.publisher(&topic::CAMPAIGN_INFO)?;
    let mut report = Every::new(ctx.diagnostics_period()?);
    let mut note: Option<String> = None;
    ctx.log(format!("source {source}, publishing on {:?}", ctx.output));
    std::thread::sleep(start_delay);

    match source.as_str() {
        "dds" => {
            let leak = |s: String| -> &'static str { Box::leak(s.into_boxed_str()) };
            let a_name = leak(
                p.string("input_actuator_topic", "/rpkm/controller/actuator_state")
                    .map_err(bp)?,
            );
            let m_name = leak(
                p.string(
                    "input_measurement_topic",
                    "/rpkm/controller/tcp_measurement",
                )
                .map_err(bp)?,
            );
            if ctx.output != Backend::Ipc
                && (a_name == topic::ACTUATOR_STATE.name()
                    || m_name == topic::TCP_MEASUREMENT.name())
            {
                return Err(crate::error::bad_input(format!(
                    "ingest: input topics {a_name}, {m_name} would also receive this node's own \
                     DDS output; use other input topics or --backend ipc"
                )));
            }
            let a_topic: Topic<ActuatorState> = Topic::new(a_name, topic::ACTUATOR_STATE.qos());
            let m_topic: Topic<TcpMeasurement> = Topic::new(m_name, Qos::reliable(256));
            let states = ctx.transport.subscriber_on(&a_topic, Backend::Dds)?;
            let measurements = ctx.transport.subscriber_on(&m_topic, Backend::Dds)?;
            let idle = super::Idle::new(Duration::from_millis(50), Duration::from_micros(500));
            let mut idle = idle;
            while !super::shutdown::requested() {
                let mut worked = false;
                while let Some(s) = states.try_recv()? {
                    worked = true;
                    match out.validator.state(&s, a_name) {
                        Ok(()) => out.publish_state(&s)?,
                        Err(r) => out.tally.reject(r),
                    }
                }
                while let Some(m) = measurements.try_recv()? {
                    worked = true;
                    match out.validator.measurement(&m, m_name) {
                        Ok(()) => {
                            out.measurements.publish(&m)?;
                            out.tally.accepted_measurements += 1;
                        }
                        Err(r) => out.tally.reject(r),
                    }
                }
                if report.due() {
                    diagnostics.publish(&diagnostic_array(
                        out.tally.status(&ctx.name, &source, None),
                    ))?;
                }
                if worked {
                    idle.worked();
                } else {
                    idle.wait();
                }
            }
        }
        "stdin" | "-" => {
            let (tx, rx) = mpsc::channel::<String>();
            std::thread::spawn(move || {
                for line in std::io::stdin().lock().lines() {
                    // A read error (not UTF-8) is a malformed line, not the end of the stream.
                    let line = line.unwrap_or_else(|e| format!("\u{0}{e}"));
                    if tx.send(line).is_err() {
                        break;
                    }
                }
            });
            let mut rows = CsvRows::new("stdin");
            let mut n = 0usize;
            let mut campaign = stub("stdin", Vec::new());
            loop {
                if super::shutdown::requested() {
                    break;
                }
                match rx.recv_timeout(Duration::from_millis(20)) {
                    Ok(line) => {
                        n += 1;
                        let had_header = rows.columns.is_some();
                        match rows.line(n, &line) {
                            None => {
                                if !had_header && rows.columns.is_some() {
                                    campaign = stub("stdin", rows.covariate_names());
                                    if let Ok(i) = campaign_info(&campaign) {
                                        info.publish(&i)?;
                                    }
                                }
                            }
                            Some(Ok(pose)) => out.pose(&campaign, &pose)?,
                            Some(Err(r)) => out.tally.reject(r),
                        }
                    }
                    Err(mpsc::RecvTimeoutError::Timeout) => {}
                    Err(mpsc::RecvTimeoutError::Disconnected) => {
                        ctx.log(format!("end of stdin after {n} lines"));
                        break;
                    }
                }
                if report.due() {
                    diagnostics.publish(&diagnostic_array(
                        out.tally.status(&ctx.name, &source, None),
                    ))?;
                }
            }
            if end_marker && !super::shutdown::requested() {
                out.end_marker()?;
            }
        }
        file => {
            let path = Path::new(file);
            let text = match std::fs::read_to_string(path) {
                Ok(t) => t,
                Err(e) => {
                    return Err(crate::error::bad_input(format!(
                        "{file}: cannot read campaign: {e}"
                    )))
                }
            };
            let period = Duration::from_secs_f64(1.0 / rate_hz);
            let t0 = Instant::now();
            let mut k = 0u32;
            let pace = |k: &mut u32| {
                let due = t0 + period * *k;
                *k += 1;
                let now = Instant::now();
                if due > now {
                    std::thread::sleep(due - now);
                }
            };
            match Campaign::parse(&text, file) {
                Ok(c) => {
                    if let Ok(i) = campaign_info(&c) {
                        info.publish(&i)?;
                    }
                    for pose in &c.poses {
                        if super::shutdown::requested() {
                            break;
                        }
                        pace(&mut k);
                        out.pose(&c, pose)?;
                        if report.due() {
                            diagnostics.publish(&diagnostic_array(
                                out.tally.status(&ctx.name, &source, None),
                            ))?;
                        }
                    }
                }
                Err(e) => {
                    // The file breaks a campaign rule: stream the rows that pass the row-level
                    // checks and report the rest, instead of publishing nothing.
                    note = Some(format!("campaign rules broken ({e}); valid rows streamed"));
                    ctx.log(note.as_deref().unwrap_or_default());
                    let mut rows = CsvRows::new(file);
                    let mut campaign = stub(file, Vec::new());
                    for (i, line) in text.lines().enumerate() {
                        if super::shutdown::requested() {
                            break;
                        }
                        let had_header = rows.columns.is_some();
                        match rows.line(i + 1, line) {
                            None => {
                                if !had_header && rows.columns.is_some() {
                                    campaign = stub(file, rows.covariate_names());
                                }
                            }
                            Some(Ok(pose)) => {
                                pace(&mut k);
                                out.pose(&campaign, &pose)?;
                            }
                            Some(Err(r)) => out.tally.reject(r),
                        }
                        if report.due() {
                            diagnostics.publish(&diagnostic_array(out.tally.status(
                                &ctx.name,
                                &source,
                                note.as_deref(),
                            )))?;
                        }
                    }
                }
            }
            if end_marker && !super::shutdown::requested() {
                out.end_marker()?;
            }
            ctx.log(format!(
                "end of {file}: {} states, {} measurements published, {} rejected",
                out.tally.accepted_states,
                out.tally.accepted_measurements,
                out.tally.rejected_total()
            ));
        }
    }
    diagnostics.publish(&diagnostic_array(out.tally.status(
        &ctx.name,
        &source,
        note.as_deref(),
    )))?;
    // Stay up after the end of the input (unless told otherwise): the launch keeps its nodes,
    // and /diagnostics keeps reporting the final counts.
    while !exit_at_end && !super::shutdown::requested() {
        std::thread::sleep(Duration::from_millis(20));
        if report.due() {
            diagnostics.publish(&diagnostic_array(out.tally.status(
                &ctx.name,
                &source,
                note.as_deref(),
            )))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(seq: u64, sec: i32) -> ActuatorState {
        ActuatorState {
            seq,
            stamp: Time { sec, nanosec: 0 },
            position: [2.6, 2.6, 0.79, 0.79],
            ..Default::default()
        }
    }

    #[test]
    fn validator_rejects_each_kind() {
        let mut v = Validator::new(Limits::default());
        assert_eq!(v.state(&state(1, 10), "t"), Ok(()));
        let mut nan = state(2, 11);
        nan.position[2] = f64::NAN;
        assert_eq!(
            v.state(&nan, "t").map_err(|r| r.kind),
            Err(RejectKind::NonFinite)
        );
        let mut far = state(2, 11);
        far.position[0] = 7.0;
        assert_eq!(
            v.state(&far, "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfRange)
        );
        let mut force = state(2, 11);
        force.force[3] = -1e6;
        assert_eq!(
            v.state(&force, "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfRange)
        );
        assert_eq!(
            v.state(&state(1, 11), "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfOrder)
        );
        assert_eq!(
            v.state(&state(3, 9), "t").map_err(|r| r.kind),
            Err(RejectKind::OutOfOrder)
        );
        // Rejected samples do not move the order reference.
        assert_eq!(v.state(&state(2, 11), "t"), Ok(()));
    }

    #[test]
    fn csv_rows_reject_and_name_the_line() {
        let mut rows = CsvRows::new("stdin");
        assert!(rows
            .line(
                1,
                "t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi,temp"
            )
            .is_none());
        let good = rows
            .line(2, "3,A,none,0,2611,2611,789,789,10,-5,0,0,23,,,,,20.5")
            .and_then(Result::ok)
            .expect("a pose");
        assert_eq!(good.q[2], 789.0);
        assert_eq!(good.follower, [false, true, true, false]);
        assert_eq!(good.covariates, vec![Some(20.5)]);
        let kind =
            |r: Option<Result<Pose, Reject>>| r.and_then(|r| r.err()).map(|r| (r.kind, r.detail));
        let (k, d) =
            kind(rows.line(3, "4,A,none,0,2611,abc,789,789,0,0,0,0,,,,,,20")).expect("reject");
        assert_eq!(k, RejectKind::Malformed);
        assert_eq!(d, "stdin:3: (q2) expected a number, found \"abc\"");
        let (k, _) =
            kind(rows.line(4, "5,A,none,0,2611,NaN,789,789,0,0,0,0,,,,,,20")).expect("reject");
        assert_eq!(k, RejectKind::NonFinite);
        let (k, _) = kind(rows.line(5, "5,A,none,0,2611")).expect("reject");
        assert_eq!(k, RejectKind::Malformed);
        assert!(rows.line(6, "# comment").is_none());
    }
}
