//! What the monitor has heard: the last message of every topic, rates, the level history,
//! and when each node last spoke. Times are seconds since the monitor started (`now`), passed
//! in by the caller, so that the struct is a plain value the unit tests drive without clocks.

use rpkm_nodes::units::{m_from_mm, ms_from_seconds};
use std::collections::{BTreeMap, VecDeque};

pub use super::rate::RateMeter;
use rpkm_msgs::{
    ActuatorState, CampaignInfo, Diagnosis, DiagnosticArray, DiagnosticStatus, Parameters,
    PreloadStatus, TcpEstimate, TcpMeasurement,
};
use serde_json::{json, Value};

/// How the monitor judges silence and how much history it keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WatchConfig {
    /// A node is silent when nothing of it (topics or /diagnostics) arrived for this long, s;
    /// longer for a node whose /diagnostics period is longer (1.5 periods).
    pub silent_after_s: f64,
    /// Time per mark of the level history, s.
    pub history_bucket_s: f64,
    /// Marks kept for the history strip.
    pub history_len: usize,
}

impl Default for WatchConfig {
    fn default() -> Self {
        Self {
            silent_after_s: 1.0,
            history_bucket_s: 0.25,
            history_len: 512,
        }
    }
}

/// Where the WARN/ERROR thresholds on screen came from.
#[derive(Debug, Clone, PartialEq)]
pub enum ThresholdSource {
    /// Not known yet: no parameter file and no report of preload_monitor heard.
    Unknown,
    /// `rpkm monitor --params FILE` (preload_monitor's section).
    ParamsFile(String),
    /// The thresholds preload_monitor names in its /diagnostics message.
    Diagnostics,
}

/// The preload monitor's thresholds on |measured − predicted| current (%) and |Δq| (m).
#[derive(Debug, Clone, PartialEq)]
pub struct MonitorThresholds {
    pub warn_percent: f64,
    pub error_percent: f64,
    /// Follower-mode compatibility thresholds, when known.
    pub dq_m: Option<(f64, f64)>,
    pub source: ThresholdSource,
}

impl MonitorThresholds {
    /// MonitorThresholds not known yet (NaN: no drive is judged against them).
    pub fn unknown() -> Self {
        Self {
            warn_percent: f64::NAN,
            error_percent: f64::NAN,
            dq_m: None,
            source: ThresholdSource::Unknown,
        }
    }

    pub fn known(&self) -> bool {
        self.source != ThresholdSource::Unknown
    }

    /// The level (PreloadStatus::OK/WARN/ERROR) of one drive's deviation, `None` while the
    /// thresholds are unknown or the drive's force is not measured (deviation NaN).
    pub fn level_of(&self, deviation_percent: f64) -> Option<u8> {
        if !self.known() || deviation_percent.is_nan() {
            return None;
        }
        let d = deviation_percent.abs();
        Some(if !(d < self.error_percent) {
            PreloadStatus::ERROR
        } else if d >= self.warn_percent {
            PreloadStatus::WARN
        } else {
            PreloadStatus::OK
        })
    }
}

/// `(warn, error)` of the first `thresholds A / B UNIT` in a preload_monitor message
/// (`ERROR: drive q3 deviates +113.2 % (...; thresholds 30 / 80 %)`).
pub fn parse_thresholds(message: &str, unit: &str) -> Option<(f64, f64)> {
    message.match_indices("thresholds ").find_map(|(at, key)| {
        let mut words = message[at + key.len()..].split_whitespace();
        let warn: f64 = words.next()?.parse().ok()?;
        (words.next()? == "/").then_some(())?;
        let error: f64 = words.next()?.parse().ok()?;
        let u = words.next()?.trim_end_matches([')', ';', ',']);
        (u == unit && warn.is_finite() && error.is_finite()).then_some((warn, error))
    })
}

/// What the monitor knows of one node.
#[derive(Debug, Clone, Default)]
pub struct NodeHealth {
    /// Last time any topic of the node or its /diagnostics arrived, s.
    pub last_heard_s: f64,
    /// Last /diagnostics status of the node and when it came.
    pub diagnostic: Option<(DiagnosticStatus, f64)>,
    /// The last intervals between its /diagnostics reports, s (the longest sets the patience).
    diag_intervals: [f64; 4],
    diag_count: usize,
}

impl NodeHealth {
    /// How long the node may stay quiet before it is called silent.
    pub fn patience_s(&self, config: &WatchConfig) -> f64 {
        let period = self.diag_intervals.iter().fold(0.0f64, |m, v| m.max(*v));
        config.silent_after_s.max(1.5 * period)
    }
}

/// The topics a node publishes, by the node's default name: a message on one of them is a
/// sign of life of that node. `/rpkm/actuator_state` is not here: a replayed bag publishes
/// it as well as ingest; nor are the calibrator's `/rpkm/parameters` and `/rpkm/diagnosis`,
/// which a replayed bag carries too (`rpkm simulate --record-parameters`, a recording): the
/// calibrator is heard by its /diagnostics.
pub const NODE_TOPICS: [(&str, &str); 2] = [
    ("/rpkm/tcp_estimate", "tcp_estimator"),
    ("/rpkm/preload_status", "preload_monitor"),
];

/// The /diagnostics status name under which `rpkm launch` reports its nodes (after the
/// set's prefix, `rpkm/launch`): one key-value per declared node, its name and its state
/// ([`GONE`], [`DONE`], `running`, `restarting`).
pub const LAUNCH_STATUS: &str = "launch";
/// Prefix of the state of a node that ended with an error and is not restarted:
/// `gone: exited with code 2`.
pub const GONE: &str = "gone: ";
/// Prefix of the state of a node that finished (exit 0): `done: exited with code 0`.
pub const DONE: &str = "done: ";
/// End of the state of an executable of the launch (`rpkm record`), which is no node: it
/// says nothing on /diagnostics and is not waited for (`running (executable)`).
pub const EXECUTABLE: &str = " (executable)";

/// What `rpkm launch` says of its nodes, in launch-file order.
#[derive(Debug, Clone, Default)]
pub struct LaunchView {
    /// Node name and state.
    pub nodes: Vec<(String, String)>,
    /// The executables of the launch (the recorder), name and state: no nodes, never heard.
    pub executables: Vec<(String, String)>,
    /// When the report came, s.
    pub heard_s: f64,
}

impl LaunchView {
    fn from_status(st: &DiagnosticStatus, now: f64) -> Self {
        let (mut nodes, mut executables) = (Vec::new(), Vec::new());
        for kv in &st.values {
            match kv.value.strip_suffix(EXECUTABLE) {
                Some(state) => executables.push((kv.key.clone(), state.to_owned())),
                None => nodes.push((kv.key.clone(), kv.value.clone())),
            }
        }
        Self {
            nodes,
            executables,
            heard_s: now,
        }
    }
}

/// Outcome counts of TcpEstimate (`outcome` 0, 1, 2) and the last fallback's reason code.
#[derive(Debug, Clone, Default)]
pub struct Outcomes {
    pub ok: u64,
    pub warm_rejected_cold_ok: u64,
    pub rigid_fallback: u64,
    /// `outcome` values outside 0..=2 (a newer publisher).
    pub unknown: u64,
    pub last_reason: Option<u8>,
}

/// Receive-to-receive latency from an ActuatorState to the TcpEstimate of the same seq, as
/// the monitor sees them (so it includes the monitor's own polling delay).
#[derive(Debug, Clone)]
pub struct Latency {
    /// Receive time of the last states, by seq modulo the ring's length.
    sent: Box<[(u64, f64)]>,
    pub last_ms: Option<f64>,
    window_max_ms: f64,
    pub max_ms: Option<f64>,
    window_start: f64,
}

impl Latency {
    const RING: usize = 8192;

    fn new() -> Self {
        Self {
            sent: vec![(u64::MAX, 0.0); Self::RING].into_boxed_slice(),
            last_ms: None,
            window_max_ms: 0.0,
            max_ms: None,
            window_start: 0.0,
        }
    }

    fn state(&mut self, seq: u64, now: f64) {
        self.sent[ring_slot(seq, Self::RING)] = (seq, now);
    }

    fn estimate(&mut self, seq: u64, now: f64) {
        let (s, t) = self.sent[ring_slot(seq, Self::RING)];
        if s != seq {
            return;
        }
        let ms = ms_from_seconds(now - t);
        self.last_ms = Some(ms);
        self.window_max_ms = self.window_max_ms.max(ms);
        if now - self.window_start >= 1.0 {
            self.max_ms = Some(self.window_max_ms);
            self.window_max_ms = 0.0;
            self.window_start = now;
        }
    }
}

/// Everything the monitor has heard.
#[derive(Debug, Clone)]
pub struct Watch {
    pub config: WatchConfig,
    pub thresholds: MonitorThresholds,
    /// Last PreloadStatus and when it arrived.
    pub preload: Option<(PreloadStatus, f64)>,
    pub preload_count: u64,
    /// The level history: per time bucket (index = now / history_bucket_s) that had a
    /// PreloadStatus, the worst held level in it; oldest first.
    pub history: VecDeque<(u64, u8)>,
    /// PreloadStatus messages per held level OK, WARN, ERROR (others not counted).
    pub level_counts: [u64; 3],
    /// When the held level was first WARN and first ERROR, s.
    pub first_warn_s: Option<f64>,
    pub first_error_s: Option<f64>,
    pub state: Option<ActuatorState>,
    pub state_count: u64,
    pub state_rate: RateMeter,
    pub last_state_s: Option<f64>,
    pub estimate: Option<TcpEstimate>,
    pub estimate_count: u64,
    pub estimate_rate: RateMeter,
    pub outcomes: Outcomes,
    pub latency: Latency,
    pub measurement_count: u64,
    pub campaign: Option<CampaignInfo>,
    pub parameters: Option<(Parameters, f64)>,
    /// When Parameters other than the first heard replaced the model, s: the WARN and
    /// ERROR raised before were the old model's, and are cleared then.
    pub model_replaced_s: Option<f64>,
    /// The model preload_monitor last said it predicts with.
    preload_model: Option<String>,
    pub diagnosis: Option<(Diagnosis, f64)>,
    /// Nodes heard so far, by name (`rpkm/<name>` on /diagnostics, or the publisher of a
    /// topic of [`NODE_TOPICS`]).
    pub nodes: BTreeMap<String, NodeHealth>,
    /// What `rpkm launch` last said of the nodes it declared, if a launch reports.
    pub launch: Option<LaunchView>,
    /// The status names of the watched set's nodes start with this (`rpkm/`, or
    /// `machine_a/` for the set in namespace /machine_a); it is left out on screen.
    status_prefix: String,
    /// Samples that could not be received (decode or transport errors), and the last one.
    pub receive_errors: u64,
    pub last_receive_error: Option<(String, f64)>,
}

impl Watch {
    pub fn new(config: WatchConfig, thresholds: MonitorThresholds) -> Self {
        Self {
            config,
            thresholds,
            preload: None,
            preload_count: 0,
            history: VecDeque::with_capacity(config.history_len),
            level_counts: [0; 3],
            first_warn_s: None,
            first_error_s: None,
            state: None,
            state_count: 0,
            state_rate: RateMeter::default(),
            last_state_s: None,
            estimate: None,
            estimate_count: 0,
            estimate_rate: RateMeter::default(),
            outcomes: Outcomes::default(),
            latency: Latency::new(),
            measurement_count: 0,
            campaign: None,
            parameters: None,
            model_replaced_s: None,
            preload_model: None,
            diagnosis: None,
            nodes: BTreeMap::new(),
            launch: None,
            status_prefix: "rpkm/".to_owned(),
            receive_errors: 0,
            last_receive_error: None,
        }
    }

    /// Watches the set in `names`'s namespace: its status names (`machine_a/ingest`).
    pub fn in_namespace(&mut self, names: &rpkm_transport::Names) {
        // the status name of a node called "x", without the "x"
        let of_x = names.status_name("x");
        of_x[..of_x.len() - 1].clone_into(&mut self.status_prefix);
    }

    fn heard_topic(&mut self, topic: &str, now: f64) {
        if let Some((_, node)) = NODE_TOPICS.iter().find(|(t, _)| *t == topic) {
            self.nodes
                .entry((*node).to_owned())
                .or_default()
                .last_heard_s = now;
        }
    }

    pub fn on_state(&mut self, s: &ActuatorState, now: f64) {
        self.state = Some(*s);
        self.state_count += 1;
        self.state_rate.count(now);
        self.last_state_s = Some(now);
        self.latency.state(s.seq, now);
    }

    pub fn on_estimate(&mut self, e: &TcpEstimate, now: f64) {
        self.heard_topic("/rpkm/tcp_estimate", now);
        self.estimate = Some(*e);
        self.estimate_count += 1;
        self.estimate_rate.count(now);
        self.latency.estimate(e.seq, now);
        let o = &mut self.outcomes;
        match e.outcome {
            TcpEstimate::OUTCOME_OK => o.ok += 1,
            TcpEstimate::OUTCOME_WARM_REJECTED_COLD_OK => o.warm_rejected_cold_ok += 1,
            TcpEstimate::OUTCOME_RIGID_FALLBACK => o.rigid_fallback += 1,
            _ => o.unknown += 1,
        }
        if e.outcome != TcpEstimate::OUTCOME_OK {
            o.last_reason = Some(e.reason);
        }
    }

    pub fn on_preload(&mut self, s: &PreloadStatus, now: f64) {
        self.heard_topic("/rpkm/preload_status", now);
        self.preload = Some((*s, now));
        self.preload_count += 1;
        if let Some(count) = self.level_counts.get_mut(usize::from(s.level)) {
            *count += 1;
        }
        let bucket = self.bucket(now);
        match self.history.back_mut() {
            Some((b, level)) if *b == bucket => *level = (*level).max(s.level),
            _ => {
                if self.history.len() >= self.config.history_len.max(1) {
                    self.history.pop_front();
                }
                self.history.push_back((bucket, s.level));
            }
        }
        if s.level >= PreloadStatus::WARN {
            self.first_warn_s.get_or_insert(now);
        }
        if s.level >= PreloadStatus::ERROR {
            self.first_error_s.get_or_insert(now);
        }
    }

    /// The history bucket of a time.
    pub fn bucket(&self, now: f64) -> u64 {
        let b = now / self.config.history_bucket_s;
        if b.is_finite() && b > 0.0 {
            rpkm_core::convert::round_u64(b.floor())
        } else {
            0
        }
    }

    pub fn on_measurement(&mut self, _m: &TcpMeasurement, _now: f64) {
        self.measurement_count += 1;
    }

    pub fn on_campaign(&mut self, c: CampaignInfo) {
        self.campaign = Some(c);
    }

    /// New Parameters replace the model the nodes predict with: the alarms the old model
    /// raised are cleared ([`Watch::model_replaced`]). The same set again changes nothing.
    pub fn on_parameters(&mut self, p: Parameters, now: f64) {
        self.heard_topic("/rpkm/parameters", now);
        if self.parameters.as_ref().is_some_and(|(old, _)| *old != p) {
            self.model_replaced(now);
        }
        self.parameters = Some((p, now));
    }

    /// The preload monitor predicts with another model now: the first WARN, first ERROR and
    /// level counts were the old model's, and are cleared; the next statuses are the new
    /// model's.
    fn model_replaced(&mut self, now: f64) {
        self.model_replaced_s = Some(now);
        self.first_warn_s = None;
        self.first_error_s = None;
        self.level_counts = [0; 3];
    }

    /// The model preload_monitor says it predicts with (its status's `parameters`: "nominal
    /// parameters", "/rpkm/parameters (model 29, ...)"): a change replaces the model, also
    /// where the first Parameters replace the nominal ones the node started with.
    fn preload_model_from_status(&mut self, st: &DiagnosticStatus, now: f64) {
        let Some(model) = st.values.iter().find(|v| v.key == "parameters") else {
            return;
        };
        if self
            .preload_model
            .as_ref()
            .is_some_and(|old| *old != model.value)
        {
            self.model_replaced(now);
        }
        self.preload_model = Some(model.value.clone());
    }

    pub fn on_diagnosis(&mut self, d: Diagnosis, now: f64) {
        self.heard_topic("/rpkm/diagnosis", now);
        self.diagnosis = Some((d, now));
    }

    /// Every status of the array: the node named `rpkm/<node>` is alive; preload_monitor's
    /// message gives the thresholds unless a parameter file did.
    pub fn on_diagnostics(&mut self, a: DiagnosticArray, now: f64) {
        for st in a.status {
            let name = st
                .name
                .strip_prefix(self.status_prefix.as_str())
                .unwrap_or(&st.name)
                .to_owned();
            if name == LAUNCH_STATUS {
                self.launch = Some(LaunchView::from_status(&st, now));
                continue;
            }
            if name == "preload_monitor" {
                self.thresholds_from_status(&st);
                self.preload_model_from_status(&st, now);
            }
            let node = self.nodes.entry(name).or_default();
            if let Some((_, at)) = node.diagnostic {
                let k = node.diag_count % node.diag_intervals.len();
                node.diag_intervals[k] = now - at;
                node.diag_count += 1;
            }
            node.last_heard_s = now;
            node.diagnostic = Some((st, now));
        }
    }

    /// The thresholds from the status's key-values (`warn_percent`, `error_percent`,
    /// `dq_warn_m`, `dq_error_m`); from the sentence when a preload_monitor older than those
    /// values sent it.
    fn thresholds_from_status(&mut self, st: &DiagnosticStatus) {
        if matches!(self.thresholds.source, ThresholdSource::ParamsFile(_)) {
            return;
        }
        let value = |key: &str| {
            st.values
                .iter()
                .find(|v| v.key == key)
                .and_then(|v| v.value.parse::<f64>().ok())
                .filter(|v| v.is_finite())
        };
        if let (Some(warn), Some(error)) = (value("warn_percent"), value("error_percent")) {
            self.thresholds.warn_percent = warn;
            self.thresholds.error_percent = error;
            self.thresholds.source = ThresholdSource::Diagnostics;
            if let (Some(w), Some(e)) = (value("dq_warn_m"), value("dq_error_m")) {
                self.thresholds.dq_m = Some((w, e));
            }
            return;
        }
        self.thresholds_from_message(&st.message);
    }

    fn thresholds_from_message(&mut self, message: &str) {
        if let Some((warn, error)) = parse_thresholds(message, "%") {
            self.thresholds.warn_percent = warn;
            self.thresholds.error_percent = error;
            self.thresholds.source = ThresholdSource::Diagnostics;
        }
        if let Some((w, e)) = parse_thresholds(message, "mm") {
            self.thresholds.dq_m = Some((m_from_mm(w), m_from_mm(e)));
        }
    }

    pub fn on_receive_error(&mut self, error: String, now: f64) {
        self.receive_errors += 1;
        self.last_receive_error = Some((error, now));
    }

    /// Closes the rate windows (call at every redraw, so that rates fall to 0 when a stream
    /// stops).
    pub fn tick(&mut self, now: f64) {
        self.state_rate.tick(now);
        self.estimate_rate.tick(now);
    }

    /// The launched nodes and executables that are gone (exited with an error and not
    /// restarted), with how they ended.
    pub fn gone(&self) -> Vec<(&str, &str)> {
        self.launch.as_ref().map_or_else(Vec::new, |l| {
            l.nodes
                .iter()
                .chain(&l.executables)
                .filter_map(|(name, state)| Some((name.as_str(), state.strip_prefix(GONE)?)))
                .collect()
        })
    }

    /// The launched nodes that run (or restart) and have not been heard yet; the launch's
    /// executables (the recorder) are no nodes and are never waited for.
    pub fn not_heard(&self) -> Vec<&str> {
        self.launch.as_ref().map_or_else(Vec::new, |l| {
            l.nodes
                .iter()
                .filter(|(name, state)| {
                    !state.starts_with(GONE)
                        && !state.starts_with(DONE)
                        && !self.nodes.contains_key(name)
                })
                .map(|(name, _)| name.as_str())
                .collect()
        })
    }

    /// The nodes heard before that have been quiet past their patience, with how long, s; a
    /// node the launch names gone is not here (it is not silent, it is not there).
    pub fn silent(&self, now: f64) -> Vec<(&str, f64)> {
        let gone = self.gone();
        self.nodes
            .iter()
            .filter(|(name, _)| !gone.iter().any(|(g, _)| g == name))
            .filter_map(|(name, n)| {
                let quiet = now - n.last_heard_s;
                (quiet > n.patience_s(&self.config)).then_some((name.as_str(), quiet))
            })
            .collect()
    }

    /// Whether the last drive state had q2 and q3 in follower mode (Δq2/Δq3 are meaningful).
    pub fn follower_mode(&self) -> bool {
        self.state.is_some_and(|s| s.follower[1] && s.follower[2])
    }

    /// Per drive (measured %, predicted %, deviation %, level by the thresholds).
    pub fn drives(&self) -> Option<[DriveRow; 4]> {
        let (s, _) = self.preload?;
        Some([0, 1, 2, 3].map(|i| {
            let d = s.deviation[i];
            (
                s.measured_current[i],
                s.predicted_current[i],
                d,
                self.thresholds.level_of(d),
            )
        }))
    }
}

/// `OK`, `WARN`, `ERROR` (PreloadStatus and DiagnosticStatus share the codes), `STALE`.
pub fn level_name(level: u8) -> &'static str {
    match level {
        0 => "OK",
        1 => "WARN",
        2 => "ERROR",
        3 => "STALE",
        _ => "?",
    }
}

/// The name of a TcpEstimate reason code (the REASON_* constants).
pub fn reason_name(code: u8) -> &'static str {
    match code {
        0 => "none",
        1 => "not_converged",
        2 => "loop_closure",
        3 => "force_balance",
        4 => "force_limit",
        5 => "platform_angle",
        6 => "far_from_rigid",
        _ => "unknown",
    }
}

/// A finite number as JSON, else null (JSON has no NaN).
fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

impl Watch {
    /// The snapshot `rpkm monitor --once --json` prints (SI units as on the topics, currents
    /// in %).
    pub fn snapshot(&self, now: f64) -> Value {
        json!({
            "elapsed_s": now,
            "preload": self.preload_json(),
            "thresholds": self.thresholds_json(),
            "follower_mode": self.follower_mode(),
            "actuator_state": {
                "count": self.state_count,
                "rate_hz": self.state_rate.rate_hz(),
                "last_seq": self.state.map(|s| s.seq),
            },
            "tcp_estimate": self.estimate_json(),
            "tcp_measurement_count": self.measurement_count,
            "parameters": self.parameters.as_ref().map(|(p, _)| parameters_json(p)),
            "diagnosis": self.diagnosis.as_ref().map(|(d, _)| diagnosis_json(d)),
            "nodes": self.nodes_json(now),
            "receive_errors": self.receive_errors,
            "last_receive_error": self.last_receive_error.as_ref().map(|(e, _)| e.clone()),
            "silent": self.silent(now).iter().map(|(n, _)| *n).collect::<Vec<_>>(),
            "launch": self.launch.as_ref().map(|l| {
                let entry = |(name, state): &(String, String), executable: bool| {
                    json!({"name": name, "state": state, "executable": executable})
                };
                l.nodes
                    .iter()
                    .map(|n| entry(n, false))
                    .chain(l.executables.iter().map(|e| entry(e, true)))
                    .collect::<Vec<_>>()
            }),
            "model_replaced_s": self.model_replaced_s,
            "gone": self
                .gone()
                .iter()
                .map(|(name, how)| json!({"name": name, "how": how}))
                .collect::<Vec<_>>(),
            "not_heard": self.not_heard(),
        })
    }

    fn preload_json(&self) -> Value {
        let Some((s, _)) = self.preload else {
            return Value::Null;
        };
        let drives: Vec<Value> = self
            .drives()
            .into_iter()
            .flatten()
            .enumerate()
            .map(|(i, (m, p, d, l))| {
                json!({
                    "drive": format!("q{}", i + 1),
                    "measured_percent": num(m),
                    "predicted_percent": num(p),
                    "deviation_percent": num(d),
                    "level": l.map(level_name),
                })
            })
            .collect();
        let count = |l: usize| self.level_counts[l];
        json!({
            "count": self.preload_count,
            "level": level_name(s.level),
            "drives": drives,
            "dq2_m": num(s.dq2),
            "dq3_m": num(s.dq3),
            "history": {"OK": count(0), "WARN": count(1), "ERROR": count(2)},
            "first_warn_s": self.first_warn_s,
            "first_error_s": self.first_error_s,
        })
    }

    fn thresholds_json(&self) -> Value {
        let t = &self.thresholds;
        let source = match &t.source {
            ThresholdSource::Unknown => "unknown".to_owned(),
            ThresholdSource::ParamsFile(f) => format!("params {f}"),
            ThresholdSource::Diagnostics => "preload_monitor /diagnostics".to_owned(),
        };
        json!({
            "warn_percent": num(t.warn_percent),
            "error_percent": num(t.error_percent),
            "dq_warn_m": t.dq_m.map(|d| d.0),
            "dq_error_m": t.dq_m.map(|d| d.1),
            "source": source,
        })
    }

    fn estimate_json(&self) -> Value {
        let o = &self.outcomes;
        json!({
            "count": self.estimate_count,
            "rate_hz": self.estimate_rate.rate_hz(),
            "last": self.estimate.map(|e| json!({
                "seq": e.seq, "x_m": num(e.x), "y_m": num(e.y), "psi_rad": num(e.psi),
                "converged": e.converged, "outcome": e.outcome,
                "reason": reason_name(e.reason),
            })),
            "outcomes": {
                "ok": o.ok,
                "warm_rejected_cold_ok": o.warm_rejected_cold_ok,
                "rigid_fallback": o.rigid_fallback,
                "unknown": o.unknown,
            },
            "last_fallback_reason": o.last_reason.map(reason_name),
            "latency_ms": {"last": self.latency.last_ms, "max_last_second": self.latency.max_ms},
        })
    }

    fn nodes_json(&self, now: f64) -> Value {
        let nodes: Vec<Value> = self
            .nodes
            .iter()
            .map(|(name, n)| {
                let quiet = now - n.last_heard_s;
                json!({
                    "name": name,
                    "quiet_s": quiet,
                    "silent": quiet > n.patience_s(&self.config),
                    "level": n.diagnostic.as_ref().map(|(d, _)| level_name(d.level)),
                    "message": n.diagnostic.as_ref().map(|(d, _)| d.message.clone()),
                })
            })
            .collect();
        Value::Array(nodes)
    }
}

fn parameters_json(p: &Parameters) -> Value {
    json!({
        "model": p.model,
        "measurement_count": p.measurement_count,
        "cal_rms_m": num(p.cal_rms),
        "val_rms_m": num(p.val_rms),
        "max_abs_residual_m": num(p.max_abs_residual),
        "condition_number": num(p.condition_number),
        "condition": rpkm_nodes::words::condition(p.condition_number, None),
        "active_effects": p.active_effects,
        "identified": p.names.iter().zip(&p.sigmas).filter(|(_, s)| **s > 0.0).count(),
    })
}

fn diagnosis_json(d: &Diagnosis) -> Value {
    json!({
        "missing_effect": d.missing_effect,
        "significant": d.candidates.iter().filter(|c| c.significant)
            .map(|c| c.effect.clone()).collect::<Vec<_>>(),
        "candidates": d.candidates.len(),
        "baseline_val_rms_m": num(d.baseline_val_rms),
        "noise_floor_m": num(d.noise_floor),
    })
}

#[cfg(test)]
mod tests;

/// The slot of sequence number `seq` in a ring of `len` entries.
fn ring_slot(seq: u64, len: usize) -> usize {
    // usize is at most 64 bits: the remainder is below `len`, so it fits.
    usize::try_from(seq % len as u64).unwrap_or(0)
}

/// One drive's row: measured %, predicted %, deviation %, level by the thresholds.
pub type DriveRow = (f64, f64, f64, Option<u8>);
