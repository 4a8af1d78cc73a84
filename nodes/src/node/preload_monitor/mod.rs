//! `preload_monitor`: for every ActuatorState, the drive forces the elasto-geometric model
//! predicts with the current parameters (`rpkm_core::elastic::fegm`, followers as flagged)
//! against the measured ones, as redundancy currents (% of 8,600 N). The largest
//! |measured − predicted| over the drives sets the level: WARN from `warn_percent`, ERROR from
//! `error_percent`; with q2 and q3 in follower mode the compatibility test adds
//! Δq = rgm(q1, q4) − q_measured for q2 and q3 against `dq_warn_m` / `dq_error_m`. A level
//! holds after `debounce_samples` consecutive samples agree. Published: PreloadStatus every
//! `status_every` samples and at each level change, /diagnostics every period and at each
//! level change, naming the drive.
//!
//! The prediction comes from the core's guarded solve (`fegm_checked_after`: warm, else cold,
//! each checked against physics). A state without a plausible prediction is skipped and counted
//! (`implausible` on /diagnostics): it never sets a level, so a non-physical branch of the
//! solver (10⁸ N "predicted") cannot raise ERROR on a drive.
//!
//! A holding drive whose force is not measured (NaN: a cell without force sensing) has its
//! measured current and deviation NaN and sets no level; the followers' Δq (positions alone)
//! is still checked. The node says so once (log and /diagnostics, not an alarm), and every
//! report names the drives (`forces_not_measured` counts the states). A calibrated effect
//! that reads an unmeasured force skips the state (`skipped_unmeasured`, named).
//!
//! Files: `mod.rs` the monitor and the node, `tests.rs` its tests.

use super::lifecycle::Lifecycle;
use std::time::Duration;

use rpkm_core::elastic::{
    fegm_checked_after, Checked, ElasticError, Limits, NOMINAL_DRIVE_FORCE_N,
};
use rpkm_core::geometry::rgm;
use rpkm_msgs::{ActuatorState, DiagnosticArray, DiagnosticStatus, PreloadLevel, PreloadStatus};
use rpkm_transport::topic;

use super::context::{bad_param, status, CommonArgs, Every, Idle, NodeContext};
use super::declare::{keys, served, ParamBound, ParamDefault, ParamSpec};
use super::geometry::Geometry;
use super::geometry::GEOMETRY;
use super::inputs::{self, DriveInput, ParameterFollower, SeqGaps, StreamMotion, UnmeasuredForce};
use super::params::NodeParams;
use super::params::SAMPLE_COUNT;
use super::realtime::BUSY_POLL;
use crate::units::{mm_from_m, seconds_from_ms, set_follower_offsets_mm};

// > 0 without an upper bound: no descriptor range, the node's check says it.
const WARN_PERCENT: ParamSpec = ParamSpec::live(
    "warn_percent",
    ParamDefault::F64(20.0),
    "WARN from this |measured - predicted| redundancy current",
)
.unit("% of 8,600 N")
.bound(ParamBound::Positive);
const ERROR_PERCENT: ParamSpec = ParamSpec::live(
    "error_percent",
    ParamDefault::F64(50.0),
    "ERROR from this deviation (>= warn_percent)",
)
.unit("%")
.bound(ParamBound::Positive);
const DQ_WARN: ParamSpec = ParamSpec::live(
    "dq_warn_m",
    ParamDefault::F64(50e-6),
    "WARN from this |dq2|, |dq3| of the followers",
)
.unit("m")
.bound(ParamBound::Positive);
const DQ_ERROR: ParamSpec = ParamSpec::live(
    "dq_error_m",
    ParamDefault::F64(200e-6),
    "ERROR from this |dq2|, |dq3| (>= dq_warn_m)",
)
.unit("m")
.bound(ParamBound::Positive);
// Bounded (1 to a million) where read: 0 was silently taken as 1.
const DEBOUNCE: ParamSpec = ParamSpec::live(
    "debounce_samples",
    ParamDefault::U64(3),
    "consecutive samples before a level is taken",
)
.bound(ParamBound::Count(SAMPLE_COUNT.0, SAMPLE_COUNT.1));
const STATUS_EVERY: ParamSpec = ParamSpec::live(
    "status_every",
    ParamDefault::U64(1),
    "PreloadStatus every this many samples (and at every level change)",
)
.bound(ParamBound::Count(SAMPLE_COUNT.0, SAMPLE_COUNT.1));

/// The node's own parameters (thresholds live, the busy poll needs a restart).
pub const PARAMS: [ParamSpec; 7] = [
    WARN_PERCENT,
    ERROR_PERCENT,
    DQ_WARN,
    DQ_ERROR,
    DEBOUNCE,
    STATUS_EVERY,
    BUSY_POLL,
];

/// Levels and hold time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    /// |deviation| of a drive's redundancy current for WARN, %.
    pub warn_percent: f64,
    /// ... for ERROR, %.
    pub error_percent: f64,
    /// |Δq2|, |Δq3| in follower mode for WARN, m.
    pub dq_warn_m: f64,
    /// ... for ERROR, m.
    pub dq_error_m: f64,
    /// Consecutive samples before a level is taken (>= 1).
    pub debounce_samples: u32,
}

impl Default for Thresholds {
    /// The parameters' defaults.
    fn default() -> Self {
        Self {
            warn_percent: WARN_PERCENT.default_f64(),
            error_percent: ERROR_PERCENT.default_f64(),
            dq_warn_m: DQ_WARN.default_f64(),
            dq_error_m: DQ_ERROR.default_f64(),
            debounce_samples: u32::try_from(DEBOUNCE.default_u64()).unwrap_or(u32::MAX),
        }
    }
}

impl Thresholds {
    /// The /diagnostics key-values of the thresholds (`warn_percent`, `error_percent`,
    /// `dq_warn_m`, `dq_error_m`, as the parameters are named), written so that they parse
    /// back to the same f64: a viewer reads them instead of the sentence.
    pub fn values(&self) -> [(&'static str, String); 4] {
        [
            ("warn_percent", self.warn_percent.to_string()),
            ("error_percent", self.error_percent.to_string()),
            ("dq_warn_m", self.dq_warn_m.to_string()),
            ("dq_error_m", self.dq_error_m.to_string()),
        ]
    }
}

fn level_u8(l: PreloadLevel) -> u8 {
    match l {
        PreloadLevel::Ok => PreloadStatus::OK,
        PreloadLevel::Warn => PreloadStatus::WARN,
        PreloadLevel::Error => PreloadStatus::ERROR,
    }
}

/// One evaluated sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvaluatedSample {
    /// The message (its `level` is the held level).
    pub status: PreloadStatus,
    /// Level of this sample alone.
    pub sample_level: PreloadLevel,
    /// Index 0..=3 of the drive with the largest |deviation|.
    pub worst_drive: usize,
    /// Whether the held level changed with this sample.
    pub changed: bool,
}

/// The monitor's state.
#[derive(Debug, Clone)]
pub struct Monitor {
    geometry: Geometry,
    thresholds: Thresholds,
    previous: Option<Checked>,
    level: PreloadLevel,
    run_warn: u32,
    run_error: u32,
    run_ok: u32,
    /// States evaluated.
    pub samples: u64,
    /// States the model could not solve.
    pub unsolved: u64,
    /// States whose only elastic solutions failed the plausibility checks (skipped).
    pub implausible: u64,
    /// The last evaluation.
    pub last: Option<EvaluatedSample>,
    /// Gaps in the input's seq (states lost before they reached the monitor).
    pub input: SeqGaps,
    /// How the stream's carriers moved (what a calibrated effect may read).
    motion: StreamMotion,
    /// States with a holding drive's force not measured (its current not checked).
    pub forces_not_measured: u64,
    /// States skipped: a calibrated effect reads a force they do not measure; the last why.
    pub skipped_unmeasured: (u64, Option<UnmeasuredForce>),
}

impl Monitor {
    /// A monitor at level OK.
    pub fn new(geometry: Geometry, thresholds: Thresholds) -> Self {
        Self {
            geometry,
            thresholds,
            previous: None,
            level: PreloadLevel::Ok,
            run_warn: 0,
            run_error: 0,
            run_ok: 0,
            samples: 0,
            unsolved: 0,
            implausible: 0,
            last: None,
            input: SeqGaps::default(),
            motion: StreamMotion::default(),
            forces_not_measured: 0,
            skipped_unmeasured: (0, None),
        }
    }

    /// The current geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// Replaces the geometry (new Parameters).
    pub fn set_geometry(&mut self, g: Geometry) {
        self.geometry = g;
        self.previous = None;
    }

    /// Replaces the thresholds (a parameter set); the held level is taken again from the
    /// next samples.
    pub fn set_thresholds(&mut self, t: Thresholds) {
        self.thresholds = t;
    }

    /// The held level.
    pub fn level(&self) -> PreloadLevel {
        self.level
    }

    /// Evaluates one state; `None` when the model has no plausible prediction for it
    /// (counted as unsolved or implausible; the held level stays as it was).
    pub fn evaluate(&mut self, s: &ActuatorState) -> Option<EvaluatedSample> {
        self.input.next(s.seq);
        // the carriers and parameters under the calibrated effects
        let (params, q) = match self.motion.model_inputs(&mut self.geometry, s) {
            Ok(inputs) => inputs,
            Err(e) => {
                self.skipped_unmeasured = (self.skipped_unmeasured.0 + 1, Some(e));
                return None;
            }
        };
        let g = &self.geometry;
        let prev = self.previous.as_ref();
        let limits = Limits::default();
        let solved = fegm_checked_after(&params, &g.stiffness, q, s.follower, prev, &limits);
        let eq = match solved {
            Ok(solved) => {
                self.previous = Some(solved);
                solved.eq
            }
            Err(e) => {
                self.previous = None;
                match e {
                    ElasticError::Implausible(_) => self.implausible += 1,
                    _ => self.unsolved += 1,
                }
                return None;
            }
        };
        self.samples += 1;
        let to_percent = |f: f64| f / NOMINAL_DRIVE_FORCE_N * 100.0;
        // dq2, dq3 NaN, "not measured", unless q2 and q3 follow: 0 would read as perfectly
        // compatible
        let mut st = PreloadStatus {
            stamp: s.stamp,
            dq2: f64::NAN,
            dq3: f64::NAN,
            ..Default::default()
        };
        for i in 0..4 {
            st.measured_current[i] = if s.follower[i] {
                0.0
            } else {
                to_percent(s.force[i])
            };
            st.predicted_current[i] = to_percent(eq.drive_force[i]);
            // NaN where the force is not measured: no deviation, no level
            st.deviation[i] = st.measured_current[i] - st.predicted_current[i];
        }
        if st.deviation.iter().any(|d| d.is_nan()) {
            self.forces_not_measured += 1;
        }
        let worst_drive = (0..4)
            .filter(|&i| !st.deviation[i].is_nan())
            .max_by(|&a, &b| st.deviation[a].abs().total_cmp(&st.deviation[b].abs()))
            .unwrap_or(0);
        // NaN when no drive's force is measured: OK, the Δq below may still raise it
        let worst = st.deviation[worst_drive].abs();
        let t = self.thresholds;
        let mut sample_level = level_by(worst, t.warn_percent, t.error_percent);
        if s.follower[1] && s.follower[2] {
            if let Ok([q2, q3]) = rgm(&params, g.model, q[0], q[3]) {
                set_follower_offsets_mm(&mut st, [q2 - q[1], q3 - q[2]]);
                let dq = st.dq2.abs().max(st.dq3.abs());
                sample_level = sample_level.max(level_by(dq, t.dq_warn_m, t.dq_error_m));
            }
        }
        let held = self.debounced(sample_level);
        let changed = held != self.level;
        self.level = held;
        st.level = level_u8(held);
        let e = EvaluatedSample {
            status: st,
            sample_level,
            worst_drive,
            changed,
        };
        self.last = Some(e);
        Some(e)
    }

    /// The level held after this sample's: a level is taken once `debounce_samples` samples
    /// in a row reached it.
    fn debounced(&mut self, sample_level: PreloadLevel) -> PreloadLevel {
        let bump = |run: &mut u32, on: bool| *run = if on { run.saturating_add(1) } else { 0 };
        bump(&mut self.run_error, sample_level >= PreloadLevel::Error);
        bump(&mut self.run_warn, sample_level >= PreloadLevel::Warn);
        bump(&mut self.run_ok, sample_level == PreloadLevel::Ok);
        let d = self.thresholds.debounce_samples.max(1);
        if self.run_error >= d {
            PreloadLevel::Error
        } else if self.run_warn >= d {
            PreloadLevel::Warn
        } else if self.run_ok >= d {
            PreloadLevel::Ok
        } else {
            self.level
        }
    }

    /// The /diagnostics status: the held level, naming the worst drive. Lost input states
    /// are counted in the values (`input_lost`, ...), not in the level: the level is the
    /// preload's.
    pub fn status(&self, node: &str) -> DiagnosticStatus {
        let t = self.thresholds;
        let level = match self.level {
            PreloadLevel::Ok => DiagnosticStatus::OK,
            PreloadLevel::Warn => DiagnosticStatus::WARN,
            PreloadLevel::Error => DiagnosticStatus::ERROR,
        };
        let Some(e) = self.last else {
            return status(
                level,
                node,
                format!(
                    "no drive state evaluated yet ({} unsolved, {} implausible)",
                    self.unsolved, self.implausible
                ),
                [
                    ("unsolved", self.unsolved.to_string()),
                    ("implausible", self.implausible.to_string()),
                ]
                .into_iter()
                .chain(t.values())
                .chain(self.input.values())
                .collect(),
            );
        };
        let st = &e.status;
        let k = e.worst_drive;
        let name = ["OK", "WARN", "ERROR"][usize::from(st.level.min(2))];
        let mut force = format!(
            "drive q{} deviates {:+.1} % (measured {:.1} %, predicted {:.1} %; thresholds \
             {} / {} %)",
            k + 1,
            st.deviation[k],
            st.measured_current[k],
            st.predicted_current[k],
            t.warn_percent,
            t.error_percent
        );
        if let Some(why) = self.unmeasured_text(st) {
            force = why;
        }
        // In follower mode the level may come from the compatibility of q2, q3 instead.
        let (dq_drive, dq) = if st.dq2.abs() >= st.dq3.abs() {
            (2, st.dq2)
        } else {
            (3, st.dq3)
        };
        let message = if dq.abs() >= t.dq_warn_m {
            format!(
                "{name}: follower q{dq_drive} is {:+.3} mm off the rigid model (thresholds \
                 {} / {} mm); {force}",
                mm_from_m(dq),
                mm_from_m(t.dq_warn_m),
                mm_from_m(t.dq_error_m)
            )
        } else {
            format!("{name}: {force}")
        };
        let mut values = vec![
            ("worst_drive", format!("q{}", k + 1)),
            ("samples", self.samples.to_string()),
            ("unsolved", self.unsolved.to_string()),
            ("implausible", self.implausible.to_string()),
            ("forces_not_measured", self.forces_not_measured.to_string()),
            ("skipped_unmeasured", self.skipped_unmeasured.0.to_string()),
            ("dq2_m", format!("{:e}", st.dq2)),
            ("dq3_m", format!("{:e}", st.dq3)),
            ("parameters", self.geometry.source.clone()),
        ];
        values.extend(t.values());
        values.extend(self.input.values());
        for (i, keys) in DRIVE_KEYS.iter().enumerate() {
            values.push((keys[0], format!("{:.3}", st.measured_current[i])));
            values.push((keys[1], format!("{:.3}", st.predicted_current[i])));
            values.push((keys[2], format!("{:.3}", st.deviation[i])));
        }
        status(level, node, message, values)
    }

    /// Why the currents of `st` are silent, where a holding drive's force is not measured
    /// (and a state skipped for an effect that reads one); None while every force is.
    fn unmeasured_text(&self, st: &PreloadStatus) -> Option<String> {
        let drives: Vec<String> = (0..4)
            .filter(|&i| st.measured_current[i].is_nan())
            .map(|i| format!("q{}", i + 1))
            .collect();
        let skipped = self
            .skipped_unmeasured
            .1
            .as_ref()
            .map(|e| format!("; {} states skipped: {e}", self.skipped_unmeasured.0));
        (!drives.is_empty() || skipped.is_some()).then(|| {
            format!(
                "drive forces of {} not measured (a cell without force sensing): their \
                 redundancy currents are not checked, the followers' Δq still are{}",
                drives.join(", "),
                skipped.unwrap_or_default()
            )
        })
    }
}

/// What the node reads from its parameters; built at start and again for every set through
/// the parameter services (the same bounds either way).
struct Config {
    thresholds: Thresholds,
    status_every: u64,
    geometry: Geometry,
}

/// The thresholds of a parameter set, each value checked against its declaration.
fn thresholds(p: &NodeParams) -> Result<Thresholds, super::params::ParamError> {
    Ok(Thresholds {
        warn_percent: WARN_PERCENT.f64(p)?,
        error_percent: ERROR_PERCENT.f64(p)?,
        dq_warn_m: DQ_WARN.f64(p)?,
        dq_error_m: DQ_ERROR.f64(p)?,
        debounce_samples: DEBOUNCE.u64(p)?.try_into().unwrap_or(u32::MAX),
    })
}

fn configure(p: &NodeParams) -> anyhow::Result<Config> {
    let thresholds = thresholds(p).map_err(bad_param)?;
    if thresholds.error_percent < thresholds.warn_percent {
        return Err(crate::error::bad_input(format!(
            "preload_monitor: error_percent {} below warn_percent {}",
            thresholds.error_percent, thresholds.warn_percent
        )));
    }
    if thresholds.dq_error_m < thresholds.dq_warn_m {
        return Err(crate::error::bad_input(format!(
            "preload_monitor: dq_error_m {} below dq_warn_m {}",
            thresholds.dq_error_m, thresholds.dq_warn_m
        )));
    }
    let status_every = STATUS_EVERY.u64(p).map_err(bad_param)?;
    Ok(Config {
        thresholds,
        status_every,
        geometry: Geometry::from_params(p)?,
    })
}

/// The /diagnostics keys of each drive: measured, predicted and deviation, % of nominal.
const DRIVE_KEYS: [[&str; 3]; 4] = [
    [
        "q1_measured_percent",
        "q1_predicted_percent",
        "q1_deviation_percent",
    ],
    [
        "q2_measured_percent",
        "q2_predicted_percent",
        "q2_deviation_percent",
    ],
    [
        "q3_measured_percent",
        "q3_predicted_percent",
        "q3_deviation_percent",
    ],
    [
        "q4_measured_percent",
        "q4_predicted_percent",
        "q4_deviation_percent",
    ],
];

/// The level of `value` against its WARN and ERROR thresholds.
fn level_by(value: f64, warn: f64, error: f64) -> PreloadLevel {
    if value >= error {
        PreloadLevel::Error
    } else if value >= warn {
        PreloadLevel::Warn
    } else {
        PreloadLevel::Ok
    }
}

/// The node's parameters on its ROS 2 parameter services (thresholds and model live).
fn specs() -> Vec<ParamSpec> {
    served(&[&PARAMS, &GEOMETRY])
}

/// Logs the input's losses since the last report: once per report, not per gap (a stall
/// loses in bursts).
fn report_loss(ctx: &NodeContext, monitor: &Monitor, lost_reported: &mut u64) {
    if monitor.input.lost > *lost_reported {
        *lost_reported = monitor.input.lost;
        ctx.log(format!(
            "WARN: {}",
            monitor.input.summary().unwrap_or_default()
        ));
    }
}

/// A lifecycle configure: the parameters read again from the node's files.
fn reconfigure(args: &CommonArgs, ctx: &NodeContext, declared: &[&str]) -> Result<Config, String> {
    ctx.reread_params(args, "preload_monitor", declared)
        .and_then(|p| configure(&p))
        .map_err(|e| crate::error::error_chain(&e))
}

/// Every parameter the node declares besides the common ones.
pub fn declarations() -> Vec<ParamSpec> {
    inputs::with_drive_input([PARAMS.as_slice(), &GEOMETRY].concat())
}

/// Every parameter key the node declares besides the common ones.
pub fn declared() -> Vec<&'static str> {
    keys(&[&declarations()])
}

/// Applies a parameter set the services accepted: thresholds, `status_every`, the geometry,
/// the drive input's followers.
fn apply_set(
    ctx: &NodeContext,
    (p, names): (NodeParams, Vec<String>),
    (monitor, status_every, input): (&mut Monitor, &mut u64, &mut DriveInput),
) -> anyhow::Result<()> {
    let c = configure(&p)?;
    monitor.set_thresholds(c.thresholds);
    *status_every = c.status_every;
    if names.iter().any(|k| super::geometry::is_geometry_key(k)) {
        monitor.set_geometry(c.geometry);
    }
    input.configure(ctx, &p)?;
    ctx.log(format!("parameters set: {}", names.join(", ")));
    Ok(())
}

/// The node's /diagnostics status with its input's.
fn report(ctx: &NodeContext, monitor: &Monitor, input: &mut DriveInput) -> DiagnosticArray {
    let mut status = monitor.status(&ctx.status_name);
    input.annotate(&mut status);
    ctx.diagnostics(status)
}

/// Runs the node until SIGINT/SIGTERM.
pub fn run(args: &CommonArgs) -> anyhow::Result<()> {
    let declared = declared();
    let extra = inputs::extra_backend(args, "preload_monitor")?;
    let ctx = NodeContext::open("preload_monitor", args, &declared, extra)?;
    let p = &ctx.params;
    let Config {
        thresholds,
        mut status_every,
        geometry,
    } = configure(p)?;
    let busy = BUSY_POLL.f64(p).map_err(bad_param)?;
    let mut input = DriveInput::open(&ctx)?;
    let mut live = input.start_params(&ctx, specs(), |p| configure(p).map(|_| ()))?;
    let mut parameters = ParameterFollower::open(&ctx)?;
    let statuses = ctx.publisher(&topic::PRELOAD_STATUS)?;
    let diagnostics = ctx.publisher(&topic::DIAGNOSTICS)?;
    let services = super::calibration_services::CalibrationServices::open(&ctx)?;
    let mut lifecycle = Lifecycle::open(&ctx, super::lifecycle::start(args))?;
    ctx.started(format!(
        "monitoring with {}; WARN from {} %, ERROR from {} %",
        geometry.source, thresholds.warn_percent, thresholds.error_percent
    ));
    let mut monitor = Monitor::new(geometry, thresholds);
    // As the estimator: sleep until the publisher's wake-up, back at least every 20 ms.
    let mut idle = Idle::new(
        Duration::from_secs_f64(seconds_from_ms(busy)),
        Duration::from_millis(20),
    );
    let mut report_due = Every::new(ctx.diagnostics_period()?);
    let mut n = 0u64;
    let mut lost_reported = 0;
    while !super::shutdown::requested() {
        lifecycle.serve(&ctx, || {
            reconfigure(args, &ctx, &declared).map(|c| {
                monitor.set_thresholds(c.thresholds);
                status_every = c.status_every;
                monitor.set_geometry(c.geometry);
            })
        });
        if let Some(g) = parameters.poll(&ctx, monitor.geometry())? {
            monitor.set_geometry(g);
        }
        if let Some(set) = input.set_before_state(&mut live) {
            apply_set(&ctx, set, (&mut monitor, &mut status_every, &mut input))?;
        }
        if let Some(s) = input.next(&ctx)? {
            idle.worked();
            // an inactive node takes its input and publishes nothing
            let unmeasured_before = monitor.forces_not_measured;
            if let Some(e) = lifecycle.active().then(|| monitor.evaluate(&s)).flatten() {
                n += 1;
                if e.changed || n.is_multiple_of(status_every) {
                    statuses.publish(&e.status)?;
                }
                // said once: the first state whose forces are not measured
                let first_unmeasured = unmeasured_before == 0 && monitor.forces_not_measured == 1;
                if e.changed || first_unmeasured {
                    ctx.log(monitor.status(&ctx.status_name).message);
                    diagnostics.publish(&report(&ctx, &monitor, &mut input))?;
                }
            }
        } else {
            // Between samples only: a set costs the sample path nothing.
            if let Some(set) = live.poll() {
                apply_set(&ctx, set, (&mut monitor, &mut status_every, &mut input))?;
            }
            if let Some(g) = services
                .as_ref()
                .and_then(|s| s.poll(&ctx, monitor.geometry()))
            {
                monitor.set_geometry(g);
            }
            if report_due.due() {
                diagnostics.publish(&report(&ctx, &monitor, &mut input))?;
                report_loss(&ctx, &monitor, &mut lost_reported);
            }
            input.wait(&idle)?;
        }
    }
    ctx.log("stopping");
    Ok(())
}

#[cfg(test)]
mod tests;
