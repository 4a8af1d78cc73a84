//! `calibrator`: accumulates TcpMeasurements with the ActuatorState of the same stamp, per
//! setup, into a campaign (`crate::campaign_bag::CampaignAssembler`, the same mapping as the
//! bag tools) and runs `rpkm_core::calib::calibrate` when the campaign ends:
//! - an end-of-campaign marker (a TcpMeasurement with setup
//!   [`super::ingest::END_OF_CAMPAIGN`]: ingest sends it at the end of a file; any publisher
//!   may send it to request a calibration),
//! - `calibrate_every` measurements (0: off),
//! - `idle_end_s` seconds without a measurement (0: off).
//!
//! Setups whose name starts with `validation_prefix` are held out: they give `val_rms`. The
//! result goes out as Parameters (reliable, transient-local: late joiners get it) and, once
//! Diagnosis (`rpkm_core::diagnose`, [`diagnose`]).
//!
//! With `online: true` it also tracks the geometry live from the drive forces (issue 15,
//! [`super::online_tracker`]):
//! every `online_decimation`-th ActuatorState with all four drives position-controlled goes
//! to `rpkm_core::calib::online` on a worker thread (the loop hands it over without waiting;
//! a full hand-over queue is counted, never waited on), which publishes Parameters with their
//! σ when a parameter moved by `online_publish_sigma` σ since the last, and a WARN on
//! /diagnostics naming a step change, or a drift: a rod's creep explaining the change since
//! the drift test's reference beyond what noise alone would have (`DriftMonitor`, at a false
//! alarm of 1e-6 a check) and its change beyond `online_drift_warn_um` ("l3 +48 µm in 6 min
//! (+12.0 ± 0.3 µm/K)", or "l1..l5 alike in 2 min, the path cannot tell which: ..." where the
//! path does not name one rod).

use super::calibrate_action::{noise_si, CalibrateAction, Running};
use super::lifecycle::Lifecycle;
use super::online_tracker::{report_warning, state_name, tie_values, OnlineSettings, OnlineWorker};
use std::collections::VecDeque;
use std::time::{Duration, Instant};

use nalgebra::SMatrix;
use rpkm_core::calib::online::{OnlineOptions, TieSoFar, TIE_EVIDENCE_CHI2};
use rpkm_core::calib::{self, Calibration, Options, Selection};
use rpkm_core::campaign::Campaign;
use rpkm_core::effects::Effect;
use rpkm_core::obs;
use rpkm_core::params::Model;
use rpkm_core::params::N_PARAMS;
use rpkm_msgs::calibrate_action::{CalibrateGoal, CalibrateResult};
use rpkm_msgs::{
    ActuatorState, CampaignInfo, Diagnosis, DiagnosisCandidate, DiagnosticArray, DiagnosticStatus,
    Parameters, TcpMeasurement,
};
use rpkm_transport::dds_actions::GoalEnd;
use rpkm_transport::{topic, Publisher, Subscriber};

use super::context::{
    bad_param, diagnostic_array, status, CommonArgs, Every, Idle, NodeContext, MM_PER_M,
};
use super::geometry::{parameters_msg, Geometry};
use super::ingest::END_OF_CAMPAIGN;
use super::live::{self, LiveParams, Spec};
use super::params::NodeParams;
use crate::campaign_bag::CampaignAssembler;
use crate::error::bad_input;

/// Parameter keys of the node.
pub const KEYS: [&str; 20] = [
    "model",
    "geometry_file",
    "effects_file",
    "geometry.",
    "calibrate_every",
    "idle_end_s",
    "validation_prefix",
    "selection",
    "max_condition",
    "outlier_sigma",
    "noise_estimation",
    "state_buffer",
    "online",
    "online_decimation",
    "online_publish_sigma",
    "online_drift_warn_um",
    "online_force_sigma_n",
    "online_encoder_sigma_um",
    "history",
    "history_machine",
];

/// What the node diagnoses: the calibrated campaign (the held-out part for its validation)
/// with the model it calibrated, its effects in the model.
#[derive(Clone, Copy)]
struct Diagnosed<'a> {
    campaign: &'a Campaign,
    validation: Option<&'a Campaign>,
    calibration: &'a Calibration,
    effects: &'a [&'a dyn Effect],
    /// The stated noise the estimate starts from (as the calibration's).
    noise: &'a rpkm_core::noise::NoiseModel,
}

/// The model diagnosis of `rpkm_core::diagnose` with the node's effects in the model: what
/// `rpkm diagnose --effects ...` says of the same campaign.
fn diagnose_model(
    d: Diagnosed,
    stop: Option<calib::Stop>,
) -> Result<rpkm_core::diagnose::Diagnosis, rpkm_core::diagnose::DiagnoseError> {
    let opts = rpkm_core::diagnose::Options {
        model: d.calibration.model,
        noise: d.noise.clone(),
        stop,
        ..Default::default()
    };
    rpkm_core::diagnose::diagnose(d.campaign, d.validation, d.effects, &opts)
}

/// [`diagnose_model`], stopped as soon as `cancelled` says so: the diagnosis runs on a
/// thread of its own while this one asks `cancelled` (an action server's state, which lives
/// on this thread) every few milliseconds.
fn diagnose_until(
    d: Diagnosed,
    cancelled: &dyn Fn() -> bool,
) -> Result<rpkm_core::diagnose::Diagnosis, rpkm_core::diagnose::DiagnoseError> {
    let stop = calib::Stop::default();
    std::thread::scope(|scope| {
        let run = stop.clone();
        let worker = scope.spawn(move || diagnose_model(d, Some(run)));
        while !worker.is_finished() {
            if !stop.requested() && cancelled() {
                stop.request();
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        worker
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
}

/// A diagnosis as the Diagnosis message.
fn diagnosis_msg(d: &rpkm_core::diagnose::Diagnosis) -> Diagnosis {
    let m = |um: Option<f64>| um.map_or(f64::NAN, |v| v * 1e-6);
    let held = d.held_out.as_ref();
    Diagnosis {
        verdict_kind: serde_json::to_value(d.verdict_kind)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default(),
        verdict: crate::words::verdict(d),
        missing_effects: d.missing_effects.clone(),
        model_effects: d.model_effects.clone(),
        baseline_val_rms_relative: m(d.baseline.val_rms_relative_um),
        floor_relative: m(held.map(|h| h.floor_relative_um)),
        held_out_agrees: held.is_some_and(rpkm_core::diagnose::HeldOutCheck::agrees),
        missing_effect: d.missing_effect.clone().unwrap_or_default(),
        candidates: d
            .candidates
            .iter()
            .map(|c| DiagnosisCandidate {
                effect: c.effect.clone(),
                significant: c.significant,
                explained_fraction: c.explained_fraction,
                val_rms_before: m(c.val_rms_before_um),
                val_rms_after: m(c.val_rms_after_um),
            })
            .collect(),
        baseline_cal_rms: d.baseline.cal_rms_um * 1e-6,
        baseline_val_rms: m(d.baseline.val_rms_um),
        noise_floor: d.baseline.noise_floor_um * 1e-6,
    }
}

/// A finished calibration as messages.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The identified parameters with campaign statistics.
    pub parameters: Parameters,
    /// The diagnosis, or why there is none (`None`: not asked for).
    pub diagnosis: Option<Result<Diagnosis, String>>,
    /// The diagnosis's verdict: its kind and in words.
    pub verdict: Option<(rpkm_core::diagnose::VerdictKind, String)>,
    /// LM iterations of the final fit.
    pub iterations: usize,
    /// The noise the rows were weighted by, stated and estimated.
    pub noise: rpkm_core::variance::NoiseEstimate,
    /// The calibration itself and the campaign it calibrated (without its held-out part):
    /// what the machine's history records.
    pub calibration: Calibration,
    pub campaign: Campaign,
}

/// What one calibration of the node is asked: the campaign, and what an action's goal adds.
#[derive(Clone, Copy)]
pub struct Job<'a> {
    pub campaign: &'a Campaign,
    /// A held-out campaign of its own; `None`: the campaign's setups that start with the
    /// `validation_prefix`.
    pub validation: Option<&'a Campaign>,
    /// The effects by name (as `rpkm calibrate --effects`); `None`: every effect of the
    /// effects file.
    pub effects: Option<&'a str>,
    /// Whether the model diagnosis follows the calibration.
    pub diagnose: bool,
    /// Told of each LM iteration and noise round; it may stop the calibration.
    pub progress: Option<calib::Observer<'a>>,
    /// Called when the calibration is done and the diagnosis begins.
    pub diagnosing: Option<&'a dyn Fn()>,
    /// Asked while the diagnosis runs: true stops it (it then ends as cancelled).
    pub cancelled: Option<&'a dyn Fn() -> bool>,
}

impl<'a> Job<'a> {
    /// The campaign calibrated as the topics ask: its own held-out setups, the effects
    /// file's effects, diagnosed.
    pub fn of(campaign: &'a Campaign) -> Self {
        Self {
            campaign,
            validation: None,
            effects: None,
            diagnose: true,
            progress: None,
            diagnosing: None,
            cancelled: None,
        }
    }
}

/// Options of the calibrator.
#[derive(Debug, Clone)]
pub struct CalibratorOptions {
    /// Starting parameters and model.
    pub start: Geometry,
    /// Setups held out for validation start with this.
    pub validation_prefix: String,
    /// `map`: every parameter under its manufacturing tolerance, noise estimated from the
    /// campaign (what `rpkm calibrate` and `rpkm diagnose` do); `auto`: the thesis's
    /// observability selection under `max_condition`.
    pub selection: String,
    /// Condition-number limit of the automatic selection.
    pub max_condition: f64,
    /// Outlier threshold in σ (0: keep all).
    pub outlier_sigma: f64,
    /// The noise stated for the readings before the campaign's own estimate (the spec's
    /// defaults, with the σ the measurements state for themselves).
    pub noise: rpkm_core::noise::NoiseModel,
    /// Effects written as data (`effects_file`, docs/effects.md): every one of the file is in
    /// the model, its parameters published with the geometry.
    pub effects: Option<std::sync::Arc<crate::effects_file::EffectsFile>>,
    /// How the rows are weighted: the levels estimated from the campaign (default, as
    /// `rpkm calibrate`), or the stated ones.
    pub weighting: calib::Noise,
}

/// Splits a campaign into its calibration and validation parts.
fn split(c: &Campaign, prefix: &str) -> (Campaign, Option<Campaign>) {
    let is_val = |setup: &str| !prefix.is_empty() && setup.starts_with(prefix);
    let part = |val: bool| Campaign {
        poses: c
            .poses
            .iter()
            .filter(|p| is_val(&p.setup) == val)
            .cloned()
            .collect(),
        ..c.clone()
    };
    let val = part(true);
    (part(false), (!val.poses.is_empty()).then_some(val))
}

/// The calibration's options of the node's settings (the selection checked).
fn calibration_options(o: &CalibratorOptions) -> anyhow::Result<Options> {
    let selection = match o.selection.as_str() {
        "map" => Options::default().selection,
        "auto" => Selection::Auto {
            max_condition: o.max_condition,
        },
        other => anyhow::bail!("parameter selection `{other}`: expected `map` or `auto`"),
    };
    Ok(Options {
        model: o.start.model,
        selection,
        outlier_sigma: (o.outlier_sigma > 0.0).then_some(o.outlier_sigma),
        noise: o.noise.clone(),
        ..Default::default()
    })
}

/// Calibrates `campaign` (mm, rad) and builds the messages.
pub fn calibrate_campaign(campaign: &Campaign, o: &CalibratorOptions) -> anyhow::Result<Outcome> {
    calibrate_job(&Job::of(campaign), o)
}

/// Calibrates as `job` asks and builds the messages; a calibration its observer stopped is
/// the error `CalibrationError::Cancelled`.
pub fn calibrate_job(job: &Job, o: &CalibratorOptions) -> anyhow::Result<Outcome> {
    let (cal_part, own_val) = split(job.campaign, &o.validation_prefix);
    let val_part = job.validation.cloned().or(own_val);
    let opts = calibration_options(o)?;
    let named;
    let effects: Vec<&dyn rpkm_core::effects::Effect> = match job.effects {
        Some(list) => {
            named = crate::effects_file::parse_list(list, o.effects.as_deref())
                .map_err(|e| bad_input(format!("effects: {e}")))?;
            named.iter().map(AsRef::as_ref).collect()
        }
        None => o.effects.as_ref().map(|f| f.all()).unwrap_or_default(),
    };
    if let Some(file) = &o.effects {
        file.check(&cal_part)
            .map_err(|e| bad_input(e.to_string()))?;
    }
    let named_by = if job.effects.is_some() {
        "effects"
    } else {
        "effects_file"
    };
    let set = rpkm_core::effects::EffectSet::bind(&effects, &cal_part, &o.start.params)
        .map_err(|e| bad_input(format!("{named_by}: {e}")))?;
    let theta0 = vec![0.0; set.n_params()];
    // the calibration every command shares: tolerance prior, noise estimated from the data
    let (cal, noise) = calib::calibrate(&calib::Request {
        noise: o.weighting,
        effects: &set,
        theta0: &theta0,
        progress: job.progress,
        ..calib::Request::new(&cal_part, &o.start.params, &opts)
    })?;
    let model = (effects.as_slice(), &set);
    let parameters = parameters_of(&cal, (&cal_part, val_part.as_ref()), model, &noise)?;
    let diagnosed = Diagnosed {
        campaign: &cal_part,
        validation: val_part.as_ref(),
        calibration: &cal,
        effects: &effects,
        noise: &o.noise,
    };
    let (diagnosis, verdict) = if job.diagnose {
        if let Some(diagnosing) = job.diagnosing {
            diagnosing();
        }
        let diagnosis = match job.cancelled {
            Some(cancelled) => diagnose_until(diagnosed, cancelled),
            None => diagnose_model(diagnosed, None),
        };
        match diagnosis {
            // a stopped diagnosis is a stopped goal, not a diagnosis that failed
            Err(rpkm_core::diagnose::DiagnoseError::Cancelled) => {
                return Err(calib::CalibrationError::Cancelled.into());
            }
            Ok(d) => (
                Some(Ok(diagnosis_msg(&d))),
                Some((d.verdict_kind, crate::words::verdict(&d))),
            ),
            Err(e) => (Some(Err(e.to_string())), None),
        }
    } else {
        (None, None)
    };
    Ok(Outcome {
        parameters,
        diagnosis,
        verdict,
        iterations: cal.iterations,
        noise,
        calibration: cal,
        campaign: cal_part,
    })
}

/// The Parameters message of a calibration of `cal_part` of the model with `effects` (bound
/// to it as `set`), its held-out RMS on `val_part` by the diagnosis's own held-out judge (the
/// effects' corrections in, setup-local parameters re-fitted on the held-out setups).
fn parameters_of(
    cal: &Calibration,
    (cal_part, val_part): (&Campaign, Option<&Campaign>),
    (effects, set): (&[&dyn Effect], &rpkm_core::effects::EffectSet),
    noise: &rpkm_core::variance::NoiseEstimate,
) -> anyhow::Result<Parameters> {
    let mut sigmas = [0.0; N_PARAMS];
    for id in &cal.identified {
        sigmas[id.index] = id.sigma;
    }
    let mut msg = parameters_msg(&cal.params, cal.model, &sigmas);
    effect_parameters(&mut msg, &cal.effects);
    // Measurements, not the fit's rows: a pose gives one row per measured direction (x and y
    // of a tracker, ...), so the 194 measurements of the demo campaign made 453 rows.
    msg.measurement_count = u32::try_from(cal_part.poses.len()).unwrap_or(u32::MAX);
    // RMS over the length directions, weighted by their rows (angles and forces have other
    // units).
    let (sum, rows) = cal
        .rms
        .iter()
        .filter(|r| !r.is_angle && !r.is_force)
        .fold((0.0, 0usize), |(s, n), r| {
            (s + r.rms_after.powi(2) * r.rows as f64, n + r.rows)
        });
    msg.cal_rms = if rows > 0 {
        (sum / rows as f64).sqrt() / MM_PER_M
    } else {
        f64::NAN
    };
    let cal_errors: Vec<f64> = obs::tcp_errors_with(
        cal_part,
        &cal.params,
        cal.model,
        &set.corrections(&cal.theta),
    )
    .map(|e| e.iter().map(|e| e.value).collect())
    .unwrap_or_default();
    msg.max_abs_residual = if cal_errors.is_empty() {
        f64::NAN
    } else {
        cal_errors.iter().fold(0.0, |m: f64, e| m.max(e.abs())) / MM_PER_M
    };
    // the diagnosis's held-out judge: `rpkm diagnose` and `rpkm calibrate` report the same
    msg.val_rms = match val_part {
        Some(v) => {
            let alpha = rpkm_core::diagnose::Options::default().alpha;
            let judge =
                rpkm_core::diagnose::judge_calibration(v, noise, (effects, set), cal, alpha)
                    .map_err(|e| bad_input(format!("held-out setups: {e}")))?;
            judge.rms_um * 1e-6
        }
        None => f64::NAN,
    };
    msg.condition_number = cal.condition_number;
    Ok(msg)
}

/// The calibrated effects' parameters into the message: `effect.parameter`, SI where the
/// unit is a length in mm or µm or an angle in mrad or µrad, else in the unit the effect
/// states.
fn effect_parameters(msg: &mut Parameters, effects: &[calib::EffectEstimate]) {
    for e in effects {
        if !msg.active_effects.contains(&e.effect) {
            msg.active_effects.push(e.effect.clone());
        }
        let to_si = crate::effects_file::si_per_unit(&e.unit);
        msg.effect_parameter_names
            .push(format!("{}.{}", e.effect, e.name));
        msg.effect_parameter_values.push(e.value * to_si);
    }
}

/// The node's options with a goal's over them: its selection, its noise weighting, and the
/// noise the campaign's measurements state.
fn goal_options(
    o: &CalibratorOptions,
    goal: &CalibrateGoal,
    noise: rpkm_core::noise::NoiseModel,
) -> anyhow::Result<CalibratorOptions> {
    let selection = match goal.selection.as_str() {
        "" => o.selection.clone(),
        "map" | "auto" => goal.selection.clone(),
        other => {
            return Err(bad_input(format!(
                "selection: expected map, auto or empty (the node's), found {other:?}"
            )))
        }
    };
    let weighting = match goal.noise {
        CalibrateGoal::NOISE_NODE => o.weighting,
        CalibrateGoal::NOISE_ESTIMATE => calib::Noise::ESTIMATE,
        CalibrateGoal::NOISE_STATED => calib::Noise::Stated,
        other => {
            return Err(bad_input(format!(
                "noise: expected 0 (the node's noise_estimation), 1 (estimate) or 2 (stated), \
                 found {other}"
            )))
        }
    };
    Ok(CalibratorOptions {
        selection,
        noise,
        weighting,
        ..o.clone()
    })
}

/// The result of a goal's calibration `o`; `status` is the node's status line of it.
fn goal_result(o: &Outcome, status: &str) -> CalibrateResult {
    let (noise_groups, noise_stated, noise_estimated) = noise_si(&o.noise);
    let verdict = o.verdict.as_ref().map_or(String::new(), |(kind, _)| {
        serde_json::to_value(kind)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default()
    });
    let message = match &o.verdict {
        Some((_, words)) => format!("{status}; {words}"),
        None => status.to_owned(),
    };
    CalibrateResult {
        parameters: o.parameters.clone(),
        val_rms: o.parameters.val_rms,
        iterations: u32::try_from(o.iterations).unwrap_or(u32::MAX),
        noise_rounds: u32::try_from(o.noise.rounds).unwrap_or(u32::MAX),
        noise_groups,
        noise_stated,
        noise_estimated,
        verdict,
        message,
    }
}

/// Accumulates the campaign from the two streams.
#[derive(Debug)]
pub struct Accumulator {
    states: VecDeque<ActuatorState>,
    capacity: usize,
    assembler: CampaignAssembler,
    info: Option<CampaignInfo>,
    /// Measurements with no drive state of the same stamp (dropped).
    pub unpaired: u64,
    /// Measurements accumulated since the last calibration.
    pub measurements: u64,
    /// Poses without a measurement (instrument NONE), not kept.
    pub unmeasured: u64,
}

impl Accumulator {
    /// Keeps the last `capacity` drive states for the pairing.
    pub fn new(capacity: usize) -> Self {
        Self {
            states: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
            assembler: CampaignAssembler::new(),
            info: None,
            unpaired: 0,
            measurements: 0,
            unmeasured: 0,
        }
    }

    /// Takes a drive state (no allocation: the ring is preallocated).
    pub fn state(&mut self, s: &ActuatorState) {
        if self.states.len() == self.capacity {
            self.states.pop_front();
        }
        self.states.push_back(*s);
    }

    /// Takes the campaign description.
    pub fn info(&mut self, info: &CampaignInfo) -> anyhow::Result<()> {
        self.assembler.push_info(info)?;
        self.info = Some(info.clone());
        Ok(())
    }

    /// Whether a drive state with the stamp of `m` is buffered.
    pub fn has_state_for(&self, m: &TcpMeasurement) -> bool {
        self.states.iter().rev().any(|s| s.stamp == m.stamp)
    }

    /// Takes a measurement; `Ok(false)` when no state of its stamp is buffered. A pose
    /// without a measurement (instrument NONE: a row of a drive stream) gives the calibration
    /// no row and is not kept: an 8 kHz stream would otherwise grow the campaign by 8,000
    /// poses a second.
    pub fn measurement(&mut self, m: &TcpMeasurement) -> anyhow::Result<bool> {
        if m.instrument == TcpMeasurement::NONE {
            self.unmeasured += 1;
            return Ok(true);
        }
        let Some(state) = self.states.iter().rev().find(|s| s.stamp == m.stamp) else {
            self.unpaired += 1;
            return Ok(false);
        };
        self.assembler.push_state(state)?;
        self.assembler.push_measurement(m)?;
        self.measurements += 1;
        Ok(true)
    }

    /// The campaign so far and the noise its measurements state for themselves, the
    /// accumulator left as it is (an action's goal takes the campaign only when its
    /// calibration succeeded).
    pub fn peek(&self) -> anyhow::Result<(Campaign, rpkm_core::noise::NoiseModel)> {
        let copy = self.assembler.clone();
        let noise = copy.stated_noise(rpkm_core::noise::NoiseModel::default())?;
        Ok((copy.finish()?, noise))
    }

    /// The campaign so far and the noise its measurements state for themselves (over the
    /// spec's defaults); the accumulator starts a new one (keeping the description).
    pub fn take(&mut self) -> anyhow::Result<(Campaign, rpkm_core::noise::NoiseModel)> {
        let mut next = CampaignAssembler::new();
        if let Some(info) = &self.info {
            next.push_info(info)?;
        }
        let done = std::mem::replace(&mut self.assembler, next);
        self.measurements = 0;
        let noise = done.stated_noise(rpkm_core::noise::NoiseModel::default())?;
        Ok((done.finish()?, noise))
    }
}

/// Covariance of the start geometry (mm, rad) from the geometry file `rpkm calibrate --json`
/// writes: its `covariance` (29 × 29 in `names` order, the calibration's correlations), else,
/// for a file without one, the σ of its `identified` entries (`index`, `sigma`) without
/// correlations; the tolerance prior for what the file does not name (and for all without a
/// file). A calibration's covariance pins the combinations the forces cannot see; from the
/// tolerances the forces alone move them freely.
pub fn start_covariance(geometry_file: &str) -> anyhow::Result<SMatrix<f64, N_PARAMS, N_PARAMS>> {
    let prior = calib::Prior::default();
    let tolerance = SMatrix::from_fn(|i, j| if i == j { prior.sigma(i).powi(2) } else { 0.0 });
    if geometry_file.is_empty() {
        return Ok(tolerance);
    }
    let text = std::fs::read_to_string(geometry_file)
        .map_err(|e| bad_input(format!("{geometry_file}: cannot read parameters: {e}")))?;
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        bad_input(format!(
            "{geometry_file}:{}:{}: not JSON: {e}",
            e.line(),
            e.column()
        ))
    })?;
    if let Some(cov) = value.get("covariance") {
        return covariance_of(geometry_file, cov);
    }
    let Some(identified) = value.get("identified") else {
        return Ok(tolerance);
    };
    let entries = identified
        .as_array()
        .ok_or_else(|| bad_input(format!("{geometry_file}: `identified`: expected an array")))?;
    let mut cov = tolerance;
    for (n, e) in entries.iter().enumerate() {
        let index = e.get("index").and_then(serde_json::Value::as_u64);
        let s = e.get("sigma").and_then(serde_json::Value::as_f64);
        match (index.and_then(|i| usize::try_from(i).ok()), s) {
            (Some(i), Some(s)) if i < N_PARAMS && s.is_finite() && s > 0.0 => cov[(i, i)] = s * s,
            _ => {
                return Err(bad_input(format!(
                    "{geometry_file}: identified[{n}]: expected an `index` below {N_PARAMS} \
                     and a positive finite `sigma`, found {e}"
                )))
            }
        }
    }
    Ok(cov)
}

/// The `covariance` object of a geometry file: `names` (the 29 parameters, in the spec's
/// order) and `matrix` (29 rows of 29 finite numbers, symmetric, no negative variance).
fn covariance_of(
    file: &str,
    v: &serde_json::Value,
) -> anyhow::Result<SMatrix<f64, N_PARAMS, N_PARAMS>> {
    let bad = |what: String| bad_input(format!("{file}: covariance: {what}"));
    let names: Option<Vec<&str>> = v
        .get("names")
        .and_then(serde_json::Value::as_array)
        .map(|a| a.iter().filter_map(serde_json::Value::as_str).collect());
    if names.as_deref() != Some(&rpkm_core::params::NAMES[..]) {
        return Err(bad(format!(
            "expected `names` with the {N_PARAMS} parameters in the spec's order (l1, l4, ...)"
        )));
    }
    let rows = v
        .get("matrix")
        .and_then(serde_json::Value::as_array)
        .filter(|r| r.len() == N_PARAMS)
        .ok_or_else(|| bad(format!("expected `matrix` with {N_PARAMS} rows")))?;
    let mut cov = SMatrix::<f64, N_PARAMS, N_PARAMS>::zeros();
    for (i, row) in rows.iter().enumerate() {
        let row = row
            .as_array()
            .filter(|r| r.len() == N_PARAMS)
            .ok_or_else(|| bad(format!("matrix[{i}]: expected {N_PARAMS} numbers")))?;
        for (j, x) in row.iter().enumerate() {
            cov[(i, j)] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                bad(format!(
                    "matrix[{i}][{j}]: expected a finite number, found {x}"
                ))
            })?;
        }
    }
    for i in 0..N_PARAMS {
        if cov[(i, i)] < 0.0 {
            return Err(bad(format!(
                "matrix[{i}][{i}]: a negative variance {}",
                cov[(i, i)]
            )));
        }
        for j in 0..i {
            let (a, b) = (cov[(i, j)], cov[(j, i)]);
            if (a - b).abs() > 1e-9 * (cov[(i, i)] * cov[(j, j)]).sqrt().max(f64::MIN_POSITIVE) {
                return Err(bad(format!(
                    "matrix[{i}][{j}] = {a} but matrix[{j}][{i}] = {b}: not symmetric"
                )));
            }
        }
    }
    Ok(cov)
}

/// What a parameter set changes while the node runs: the options of the next calibration
/// (start geometry, selection, outliers, held-out prefix) and when a campaign ends.
struct Settings {
    options: CalibratorOptions,
    every: u64,
    idle_end: f64,
}

/// The calibrator's settings of a parameter set (at start-up and for every set on the
/// parameter services, by the same bounded readers).
fn configure(p: &NodeParams) -> anyhow::Result<Settings> {
    let selection = p.string("selection", "map").map_err(bad_param)?;
    if !matches!(selection.as_str(), "map" | "auto") {
        return Err(crate::error::bad_input(format!(
            "selection: expected map or auto, found {selection}"
        )));
    }
    let start = Geometry::from_params(p)?;
    Ok(Settings {
        options: CalibratorOptions {
            effects: start.effects.file().cloned(),
            start,
            validation_prefix: p.string("validation_prefix", "val").map_err(bad_param)?,
            selection,
            max_condition: p.positive("max_condition", 100.0).map_err(bad_param)?,
            outlier_sigma: p
                .f64_in("outlier_sigma", 0.0, super::params::OUTLIER_SIGMA, " σ")
                .map_err(bad_param)?,
            noise: rpkm_core::noise::NoiseModel::default(),
            weighting: if p.bool("noise_estimation", true).map_err(bad_param)? {
                calib::Noise::ESTIMATE
            } else {
                calib::Noise::Stated
            },
        },
        every: p
            .u64_in("calibrate_every", 0, super::params::MEASUREMENT_COUNT)
            .map_err(bad_param)?,
        idle_end: p
            .f64_in("idle_end_s", 0.0, super::params::DURATION_S, " s")
            .map_err(bad_param)?,
    })
}

/// The calibrator's parameters on its ROS 2 parameter services: what the next calibration
/// uses and when a campaign ends are live; the buffer and the online tracker need a restart.
fn specs() -> Vec<Spec> {
    use live::Default::{Bool, Str, F64, U64};
    use rpkm_transport::dds_params::ParamRange;
    let int = ParamRange::count;
    let float = |(lo, hi): (f64, f64)| ParamRange::Float(lo, hi);
    let fixed_in = |key, default, description, range| Spec {
        range,
        ..Spec::fixed(key, default, description)
    };
    let [model, _, geometry_file, _, _] = super::geometry::geometry_specs();
    vec![
        Spec {
            description: "model of the next calibration: 24 or 29 parameters",
            ..model
        },
        geometry_file,
        Spec::fixed(
            "effects_file",
            Str(""),
            "effects written as data (YAML, docs/effects.md) calibrated with the geometry",
        ),
        Spec::live(
            "calibrate_every",
            U64(0),
            "calibrate after N measurements, 0 for at the end marker only",
            int(super::params::MEASUREMENT_COUNT),
        ),
        Spec::live(
            "idle_end_s",
            F64(0.0),
            "end a campaign after this long without a measurement, s (0: never)",
            float(super::params::DURATION_S),
        ),
        Spec::live(
            "validation_prefix",
            Str("val"),
            "setups whose name starts with this are held out for validation",
            ParamRange::None,
        ),
        Spec::live(
            "selection",
            Str("map"),
            "map (every parameter under its tolerance) or auto (the thesis's selection)",
            ParamRange::None,
        ),
        Spec::live(
            "max_condition",
            F64(100.0),
            "condition-number limit of selection auto (> 0)",
            ParamRange::None,
        ),
        Spec::live(
            "outlier_sigma",
            F64(0.0),
            "outlier threshold, sigma (0: keep all)",
            float(super::params::OUTLIER_SIGMA),
        ),
        Spec::live(
            "noise_estimation",
            Bool(true),
            "weight the rows by the noise the campaign shows (false: the stated noise)",
            ParamRange::None,
        ),
        fixed_in(
            "state_buffer",
            U64(4096),
            "drive states kept for pairing with measurements",
            int(super::params::BUFFER_LEN),
        ),
    ]
    .into_iter()
    .chain(online_specs())
    .chain(history_specs())
    .collect()
}

/// The machine's history (read at start: the store is opened once).
fn history_specs() -> Vec<Spec> {
    use live::Default::Str;
    vec![
        Spec::fixed(
            "history",
            Str(""),
            "record each calibration and online step here: an SQLite file or a postgres:// URL",
        ),
        Spec::fixed(
            "history_machine",
            Str(""),
            "the machine's name in the history (default: the node's namespace, rpkm without)",
        ),
    ]
}

/// Records an online step or settled tie (said as `said`) in the machine's history, if the
/// node keeps one.
fn record_event(
    history: Option<&mut super::history::NodeHistory>,
    r: &super::online_tracker::OnlineReport,
    said: &str,
) -> anyhow::Result<()> {
    history.map_or(Ok(()), |h| h.event(r, said))
}

/// The machine's history of the parameters `history`, `history_machine` (None when off).
fn open_history(ctx: &NodeContext) -> anyhow::Result<Option<super::history::NodeHistory>> {
    let location = ctx.params.string("history", "").map_err(bad_param)?;
    if location.is_empty() {
        return Ok(None);
    }
    let mut machine = ctx
        .params
        .string("history_machine", "")
        .map_err(bad_param)?;
    if machine.is_empty() {
        machine = super::history::default_machine(&ctx.status_name, &ctx.name);
    }
    let h = super::history::NodeHistory::open(&location, &machine, &ctx.status_name)?;
    ctx.log(format!("history: {}", h.describe()));
    Ok(Some(h))
}

/// The online tracker's parameters (read at start: the tracker's thread is set up once).
fn online_specs() -> Vec<Spec> {
    use live::Default::{Bool, F64, U64};
    use rpkm_transport::dds_params::ParamRange;
    // the tracker's noise levels default to the core's (the calibration's stated ones)
    let tracker = OnlineOptions::default();
    let fixed_in = |key, default, description, range| Spec {
        range,
        ..Spec::fixed(key, default, description)
    };
    vec![
        Spec::fixed(
            "online",
            Bool(false),
            "track the geometry live from the drive forces",
        ),
        fixed_in(
            "online_decimation",
            U64(100),
            "online tracker: every N-th drive state",
            ParamRange::count((1, 1_000_000)),
        ),
        Spec::fixed(
            "online_publish_sigma",
            F64(1.0),
            "online tracker: publish when a parameter moved by this many sigma (> 0)",
        ),
        fixed_in(
            "online_drift_warn_um",
            F64(10.0),
            "online tracker: WARN from this drift, um",
            ParamRange::Float(0.1, 10_000.0),
        ),
        Spec::fixed(
            "online_force_sigma_n",
            F64(tracker.force_sigma_n),
            "online tracker: drive force noise, N (> 0)",
        ),
        fixed_in(
            "online_encoder_sigma_um",
            F64(tracker.encoder_sigma_mm * 1000.0),
            "online tracker: drive encoder noise, um (the forces move by the rods' stiffness)",
            ParamRange::Float(0.0, 100.0),
        ),
    ]
}

/// The node's outputs.
struct Outputs {
    parameters: Publisher<Parameters>,
    diagnosis: Publisher<Diagnosis>,
    diagnostics: Publisher<DiagnosticArray>,
}

/// What the node's loop keeps between samples.
struct Calibrator {
    acc: Accumulator,
    online: Option<OnlineWorker>,
    temp_name: String,
    last_measurement: Option<Instant>,
    calibrations: u64,
    /// The last status: level and message.
    last: (u8, String),
    /// The online tracker's step still "this or that" at its last report.
    tie: Option<TieSoFar>,
    /// The machine's history, where the node records (parameter `history`).
    history: Option<super::history::NodeHistory>,
}

/// The online tracker's settings from the parameters, if `online` is on.
fn online_settings(p: &NodeParams) -> anyhow::Result<Option<OnlineSettings>> {
    if !p.bool("online", false).map_err(bad_param)? {
        return Ok(None);
    }
    let tracker = OnlineOptions::default();
    Ok(Some(OnlineSettings {
        start_cov: start_covariance(&p.string("geometry_file", "").map_err(bad_param)?)?,
        decimation: p
            .u64_in("online_decimation", 100, (1, 1_000_000))
            .map_err(bad_param)?,
        publish_sigma: p.positive("online_publish_sigma", 1.0).map_err(bad_param)?,
        drift_warn_mm: p
            .f64_in("online_drift_warn_um", 10.0, (0.1, 10_000.0), " µm")
            .map_err(bad_param)?
            / 1000.0,
        options: OnlineOptions {
            force_sigma_n: p
                .positive("online_force_sigma_n", tracker.force_sigma_n)
                .map_err(bad_param)?,
            encoder_sigma_mm: p
                .f64_in(
                    "online_encoder_sigma_um",
                    tracker.encoder_sigma_mm * 1000.0,
                    (0.0, 100.0),
                    " µm",
                )
                .map_err(bad_param)?
                / 1000.0,
            ..tracker
        },
    }))
}

impl Calibrator {
    fn campaign_info(&mut self, info: &CampaignInfo) {
        if let Some(name) = info.covariate_names.first() {
            self.temp_name.clone_from(name);
        }
        if let Err(e) = self.acc.info(info) {
            self.last = (DiagnosticStatus::WARN, format!("campaign info: {e:#}"));
        }
    }

    fn state(&mut self, s: &ActuatorState) {
        self.acc.state(s);
        if let Some(w) = &mut self.online {
            w.offer(s);
        }
    }

    /// Publishes what the online tracker reported; whether it reported anything.
    fn online_reports(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        model: Model,
    ) -> anyhow::Result<bool> {
        let Some(w) = &self.online else {
            return Ok(false);
        };
        let mut worked = false;
        while let Ok(report) = w.rx.try_recv() {
            worked = true;
            let r = match report {
                Ok(r) => r,
                Err(e) => {
                    self.last = (DiagnosticStatus::WARN, format!("online calibration: {e}"));
                    continue;
                }
            };
            self.tie = r.tie;
            out.parameters
                .publish(&parameters_msg(&r.params, model, &r.sigma))?;
            if let Some(warning) = report_warning(&r, &self.temp_name) {
                let warning = match record_event(self.history.as_mut(), &r, &warning) {
                    Ok(()) => warning,
                    Err(e) => format!("{warning}; history: event not recorded: {e:#}"),
                };
                ctx.log(&warning);
                self.last = (DiagnosticStatus::WARN, warning);
                let mut t = vec![("online_t_s", format!("{:.3}", r.t))];
                t.extend(tie_values(&r));
                out.diagnostics.publish(&diagnostic_array(status(
                    self.last.0,
                    &ctx.status_name,
                    self.last.1.clone(),
                    t,
                )))?;
            }
        }
        Ok(worked)
    }

    /// Pairs one measurement with its state; whether the campaign ends with it.
    fn measurement(
        &mut self,
        m: &TcpMeasurement,
        states: &Subscriber<ActuatorState>,
        every: u64,
    ) -> anyhow::Result<bool> {
        if m.setup == END_OF_CAMPAIGN {
            return Ok(true);
        }
        // Its state may have arrived after the drain above (a fast publisher interleaves
        // state, measurement, state, ...): drain the states again before pairing.
        if !self.acc.has_state_for(m) {
            while let Some(s) = states.try_recv()? {
                self.acc.state(&s);
            }
        }
        match self.acc.measurement(m) {
            Ok(_) => self.last_measurement = Some(Instant::now()),
            Err(e) => self.last = (DiagnosticStatus::WARN, format!("measurement: {e:#}")),
        }
        Ok(every > 0 && self.acc.measurements >= every)
    }

    /// Takes the drive states (first: ingest publishes a pose's state before its
    /// measurement), then the measurements up to a campaign's end; (whether any came,
    /// whether a campaign ended).
    fn drain(
        &mut self,
        states: &Subscriber<ActuatorState>,
        measurements: &Subscriber<TcpMeasurement>,
        every: u64,
    ) -> anyhow::Result<(bool, bool)> {
        let mut worked = false;
        while let Some(s) = states.try_recv()? {
            self.state(&s);
            worked = true;
        }
        while let Some(m) = measurements.try_recv()? {
            if self.measurement(&m, states, every)? {
                return Ok((true, true));
            }
            worked = true;
        }
        Ok((worked, false))
    }

    /// Whether the campaign so far has been idle for `idle_end` seconds.
    fn idle_ended(&self, idle_end: f64) -> bool {
        idle_end > 0.0
            && self.acc.measurements > 0
            && self
                .last_measurement
                .is_some_and(|t| t.elapsed().as_secs_f64() >= idle_end)
    }

    /// Calibrates the campaign so far and publishes the outcome.
    fn calibrate(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        options: &CalibratorOptions,
    ) -> anyhow::Result<()> {
        let n = self.acc.measurements;
        let result = self.acc.take().and_then(|(c, noise)| {
            let stated = CalibratorOptions {
                noise,
                ..options.clone()
            };
            calibrate_campaign(&c, &stated)
        });
        self.publish(ctx, out, n, result.as_ref())
    }

    /// Publishes a calibration of `n` measurements (Parameters, Diagnosis) or why it failed,
    /// and says it on /diagnostics and in the log.
    fn publish(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        n: u64,
        result: Result<&Outcome, &anyhow::Error>,
    ) -> anyhow::Result<()> {
        self.last = match result {
            Ok(o) => {
                self.calibrations += 1;
                out.parameters.publish(&o.parameters)?;
                let recorded = self.record_calibration(o);
                match &o.diagnosis {
                    Some(Ok(d)) => out.diagnosis.publish(d)?,
                    Some(Err(e)) => ctx.log(format!("no diagnosis: {e}")),
                    None => {}
                }
                let (level, history) = match recorded {
                    Some(Ok(said)) => (DiagnosticStatus::OK, format!("; history: {said}")),
                    Some(Err(e)) => (
                        DiagnosticStatus::WARN,
                        format!("; history: not recorded: {e:#}"),
                    ),
                    None => (DiagnosticStatus::OK, String::new()),
                };
                (
                    level,
                    format!(
                        "calibration {}: {n} measurements ({} calibrated, {} held out), RMS \
                         {:.2} µm, condition {}{history}",
                        self.calibrations,
                        o.parameters.measurement_count,
                        n.saturating_sub(u64::from(o.parameters.measurement_count)),
                        o.parameters.cal_rms * 1e6,
                        crate::words::condition_short(o.parameters.condition_number)
                    ),
                )
            }
            Err(e) => (
                DiagnosticStatus::ERROR,
                format!("calibration of {n} measurements failed: {e:#}"),
            ),
        };
        ctx.log(&self.last.1);
        let values = vec![("calibrations", self.calibrations.to_string())];
        out.diagnostics.publish(&diagnostic_array(status(
            self.last.0,
            &ctx.status_name,
            self.last.1.clone(),
            values,
        )))?;
        Ok(())
    }

    /// Executes a goal of `~/calibrate`: the campaign it names, or the one collected (taken
    /// only when its calibration succeeds), calibrated by the node's options with the goal's
    /// over them; a success is published as the end marker's calibration is.
    fn execute(
        &mut self,
        ctx: &NodeContext,
        out: &Outputs,
        options: &CalibratorOptions,
        (running, goal): (Running, CalibrateGoal),
        meanwhile: &dyn Fn(),
    ) -> anyhow::Result<()> {
        let result = self.goal_outcome(options, &running, &goal, meanwhile);
        // stopped part-way (the calibration or the diagnosis), or done before the cancel
        // took effect
        let stopped = result.as_ref().err().is_some_and(|e| {
            matches!(
                e.downcast_ref::<calib::CalibrationError>(),
                Some(calib::CalibrationError::Cancelled)
            )
        });
        let cancelled = running.cancelled() || stopped;
        let (end, reply) = match (result, cancelled) {
            (_, true) => {
                let message = if stopped {
                    format!("stopped during {}", running.stage())
                } else {
                    "the work was done when the cancel was seen".to_owned()
                };
                (
                    GoalEnd::Canceled,
                    CalibrateResult {
                        message,
                        ..CalibrateResult::default()
                    },
                )
            }
            (Ok((o, n)), false) => {
                if goal.campaign_file.is_empty() {
                    // the collected campaign is calibrated: the next one starts empty
                    self.acc.take()?;
                }
                self.publish(ctx, out, n, Ok(&o))?;
                (GoalEnd::Succeeded, goal_result(&o, &self.last.1))
            }
            (Err(e), false) => {
                let reply = CalibrateResult {
                    message: crate::error::error_chain(&e),
                    ..CalibrateResult::default()
                };
                (GoalEnd::Aborted, reply)
            }
        };
        running.finish(ctx, end, reply);
        Ok(())
    }

    /// The calibration a goal asks for, and the number of measurements of its campaign.
    fn goal_outcome(
        &self,
        options: &CalibratorOptions,
        running: &Running,
        goal: &CalibrateGoal,
        meanwhile: &dyn Fn(),
    ) -> anyhow::Result<(Outcome, u64)> {
        let (campaign, noise) = if goal.campaign_file.is_empty() {
            anyhow::ensure!(
                self.acc.measurements > 0,
                "no measurements collected since the last calibration: name a campaign_file, \
                 or publish the campaign first"
            );
            self.acc.peek()?
        } else {
            let path = std::path::Path::new(&goal.campaign_file);
            let c = crate::input::read_campaign(path)?;
            (c, rpkm_core::noise::NoiseModel::default())
        };
        let validation = match goal.validation_file.as_str() {
            "" => None,
            path => Some(crate::input::read_campaign(std::path::Path::new(path))?),
        };
        let o = goal_options(options, goal, noise)?;
        // what the node answers while the goal runs, at each LM iteration and every few
        // milliseconds of the diagnosis
        let observe = |p: &calib::Progress| {
            meanwhile();
            running.observe(p)
        };
        let diagnosing = || running.diagnosing();
        let cancelled = || {
            meanwhile();
            running.cancelled()
        };
        let job = Job {
            campaign: &campaign,
            validation: validation.as_ref(),
            effects: (!goal.effects.is_empty()).then_some(goal.effects.as_str()),
            diagnose: !goal.skip_diagnosis,
            progress: Some(&observe),
            diagnosing: Some(&diagnosing),
            cancelled: Some(&cancelled),
        };
        let n = u64::try_from(campaign.poses.len()).unwrap_or(u64::MAX);
        Ok((calibrate_job(&job, &o)?, n))
    }

    /// Records a calibration in the machine's history, if the node keeps one: what changed
    /// since the previous one, or why it was not recorded.
    fn record_calibration(&mut self, o: &Outcome) -> Option<anyhow::Result<String>> {
        self.history.as_mut().map(|h| {
            h.calibration(&super::history::Calibrated {
                campaign: &o.campaign,
                calibration: &o.calibration,
                noise: &o.noise,
                val_rms_m: o.parameters.val_rms,
                verdict: o.verdict.as_ref().map(|v| v.1.as_str()),
            })
        })
    }

    /// The periodic /diagnostics status: the last message and the counts.
    fn publish_status(&self, ctx: &NodeContext, out: &Outputs) -> anyhow::Result<()> {
        let (level, message) = (self.last.0, self.last.1.clone());
        out.diagnostics.publish(&diagnostic_array(status(
            level,
            &ctx.status_name,
            message,
            self.report_values(),
        )))?;
        Ok(())
    }

    /// The periodic /diagnostics values.
    fn report_values(&self) -> Vec<(&'static str, String)> {
        let online = |f: fn(&OnlineWorker) -> u64| self.online.as_ref().map_or(0, f).to_string();
        vec![
            ("calibrations", self.calibrations.to_string()),
            ("pending_measurements", self.acc.measurements.to_string()),
            ("unpaired_measurements", self.acc.unpaired.to_string()),
            ("unmeasured_poses", self.acc.unmeasured.to_string()),
            ("online_samples", online(|w| w.offered)),
            ("online_dropped", online(|w| w.dropped)),
        ]
        .into_iter()
        .chain(self.tie.iter().flat_map(|t| {
            // a tie still open: which two, and how far the evidence has come
            [
                (
                    "online_tie",
                    format!("{} or {}", state_name(t.named), state_name(t.runner_up)),
                ),
                (
                    "online_tie_evidence_chi2",
                    format!("{:.1} of {TIE_EVIDENCE_CHI2:.1}", t.evidence.chi2),
                ),
            ]
        }))
        .collect()
    }
}

/// Runs the node until SIGINT/SIGTERM.
impl Outputs {
    fn open(ctx: &NodeContext) -> anyhow::Result<Self> {
        Ok(Self {
            parameters: ctx.publisher(&topic::PARAMETERS)?,
            diagnosis: ctx.publisher(&topic::DIAGNOSIS)?,
            diagnostics: ctx.publisher(&topic::DIAGNOSTICS)?,
        })
    }
}

impl Calibrator {
    /// A calibrator that keeps `capacity` drive states, with its online tracker if any.
    fn new(
        capacity: u64,
        online: Option<OnlineWorker>,
        history: Option<super::history::NodeHistory>,
    ) -> Self {
        Self {
            acc: Accumulator::new(usize::try_from(capacity).unwrap_or(usize::MAX)),
            online,
            temp_name: "covariate 1".to_owned(),
            last_measurement: None,
            calibrations: 0,
            last: (DiagnosticStatus::OK, "waiting for measurements".into()),
            tie: None,
            history,
        }
    }
}

pub fn run(args: &CommonArgs) -> anyhow::Result<()> {
    let ctx = NodeContext::open("calibrator", args, &KEYS, None)?;
    let p = &ctx.params;
    let Settings {
        mut options,
        mut every,
        mut idle_end,
    } = configure(p)?;
    let mut live = LiveParams::start(&ctx, &specs(), |p| configure(p).map(|_| ()))?;
    // Bounded before the ring is preallocated from it (4294967296 asked for 650 GB).
    let capacity = p
        .u64_in("state_buffer", 4096, super::params::BUFFER_LEN)
        .map_err(bad_param)?;
    let online = match online_settings(p)? {
        Some(settings) => Some(OnlineWorker::start(options.start.params, &settings)?),
        None => None,
    };
    let states = ctx.subscriber(&topic::ACTUATOR_STATE)?;
    let measurements = ctx.subscriber(&topic::TCP_MEASUREMENT)?;
    let infos = ctx.subscriber(&topic::CAMPAIGN_INFO)?;
    let out = Outputs::open(&ctx)?;
    let services = super::calibration_services::CalibrationServices::open(&ctx)?;
    let action = CalibrateAction::open(&ctx)?;
    let mut lifecycle = Lifecycle::open(&ctx, super::lifecycle::start(args))?;
    ctx.log(format!(
        "calibrating {} from {}",
        options.start.model, options.start.source
    ));
    let history = open_history(&ctx)?;
    let mut node = Calibrator::new(capacity, online, history);
    let mut idle = Idle::new(Duration::from_millis(50), Duration::from_millis(1));
    let mut report = Every::new(ctx.diagnostics_period()?);
    while !super::shutdown::requested() {
        while let Some(info) = infos.try_recv()? {
            node.campaign_info(&info);
        }
        let (mut worked, end) = node.drain(&states, &measurements, every)?;
        worked |= node.online_reports(&ctx, &out, options.start.model)?;
        // an inactive node collects its campaign and calibrates (publishes) once active
        if (end || node.idle_ended(idle_end)) && node.acc.measurements > 0 && lifecycle.active() {
            node.calibrate(&ctx, &out, &options)?;
        }
        lifecycle.serve(&ctx, || {
            ctx.reread_params(args, "calibrator", &KEYS)
                .and_then(|p| configure(&p))
                .map(|s| (options, every, idle_end) = (s.options, s.every, s.idle_end))
                .map_err(|e| crate::error::error_chain(&e))
        });
        // a goal of `~/calibrate`, executed now (the loop waits for it, as for a marker)
        if let Some(goal) = action
            .as_ref()
            .and_then(|a| a.next(&ctx, lifecycle.active()))
        {
            // the lifecycle's queries are answered while it runs; a transition waits
            node.execute(&ctx, &out, &options, goal, &|| lifecycle.answer_queries())?;
        }
        // Between calibrations: the next campaign ends and calibrates by the new settings.
        if let Some((p, names)) = live.poll() {
            Settings {
                options,
                every,
                idle_end,
            } = configure(&p)?;
            ctx.log(format!("parameters set: {}", names.join(", ")));
        }
        // the geometry the next calibration starts from
        if let Some(g) = services.as_ref().and_then(|s| s.poll(&ctx, &options.start)) {
            options.start = g;
        }
        if report.due() {
            node.publish_status(&ctx, &out)?;
            // a subscriber that joined late (rpkm monitor) gets the last Parameters now
            out.parameters.deliver_history()?;
        }
        if worked {
            idle.worked();
        } else {
            idle.wait();
        }
    }
    ctx.log("stopping");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign_bag::pose_messages;
    use rpkm_core::params::{Model, Params};
    use rpkm_twin::{Twin, TwinConfig};

    /// The calibrator's start in these tests: the nominal model 29, default stiffness, no
    /// effects.
    fn nominal_start() -> Geometry {
        Geometry {
            params: Params::nominal(),
            model: Model::M29,
            stiffness: rpkm_core::elastic::Stiffness::default(),
            source: "nominal".into(),
            effects: crate::node::effects::NodeEffects::default(),
        }
    }

    /// The calibrator with an effects file: the twin's lost motion of carrier 4 (20 µm) is
    /// calibrated with the geometry, and the Parameters carry it (SI) within 0.1 µm of the
    /// truth (its σ on this campaign is 0.02 µm: core/tests/written_effects.rs).
    #[test]
    fn parameters_carry_the_written_effects_parameters() -> anyhow::Result<()> {
        use rpkm_core::campaign::Instrument;
        use rpkm_twin::EffectKind;
        let b_true = 0.02;
        let mut twin = Twin::new(TwinConfig {
            seed: 8,
            effects: vec![(EffectKind::LostMotionQ4, b_true)],
            noise: Some(rpkm_core::noise::NoiseModel::default()),
            ..Default::default()
        })?;
        let c = twin.campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])?;
        let file = crate::effects_file::parse(
            "effects:\n  - name: lost_motion_q4\n    summary: carrier 4 lags\n    \
             params: {b: {unit: mm, prior: 0.01}}\n    dq4: \"-b * dir_q4\"\n",
            "lost.yaml",
            &[],
        )?;
        let o = CalibratorOptions {
            start: nominal_start(),
            validation_prefix: "val".into(),
            selection: "map".into(),
            max_condition: 100.0,
            outlier_sigma: 0.0,
            noise: rpkm_core::noise::NoiseModel::default(),
            effects: Some(std::sync::Arc::new(file)),
            weighting: calib::Noise::ESTIMATE,
        };
        let msg = calibrate_campaign(&c, &o)?.parameters;
        assert_eq!(msg.active_effects, ["lost_motion_q4"]);
        assert_eq!(msg.effect_parameter_names, ["lost_motion_q4.b"]);
        let b = msg.effect_parameter_values[0] * MM_PER_M;
        eprintln!("published b = {b} mm (truth {b_true})");
        assert!((b - b_true).abs() < 1e-4, "b = {b} mm");
        Ok(())
    }

    /// A goal on the campaign collected so far reads it without taking it (a cancelled goal
    /// leaves it collected); the goal's settings go over the node's, a bad one is refused
    /// with what was expected.
    #[test]
    fn a_goal_reads_the_collected_campaign_and_sets_its_options() -> anyhow::Result<()> {
        let mut twin = Twin::new(TwinConfig::default())?;
        let c = twin.campaign_by_names(&["lt"], 0)?;
        let mut acc = Accumulator::new(8);
        for (i, pose) in c.poses.iter().enumerate() {
            let (s, m) = pose_messages(&c, i, pose)?;
            acc.state(&s);
            assert!(acc.measurement(&m)?);
        }
        let (seen, _) = acc.peek()?;
        assert_eq!(acc.measurements, c.poses.len() as u64);
        let (taken, _) = acc.take()?;
        assert_eq!(seen.poses, taken.poses);
        assert_eq!(seen.poses.len(), c.poses.len());
        assert_eq!(acc.measurements, 0);

        let node = CalibratorOptions {
            start: nominal_start(),
            validation_prefix: "val".into(),
            selection: "map".into(),
            max_condition: 100.0,
            outlier_sigma: 0.0,
            noise: rpkm_core::noise::NoiseModel::default(),
            effects: None,
            weighting: calib::Noise::ESTIMATE,
        };
        let goal = |selection: &str, noise| CalibrateGoal {
            selection: selection.into(),
            noise,
            ..CalibrateGoal::default()
        };
        let noise = rpkm_core::noise::NoiseModel::default;
        let o = goal_options(&node, &goal("", CalibrateGoal::NOISE_NODE), noise())?;
        assert_eq!(
            (o.selection.as_str(), o.weighting),
            ("map", calib::Noise::ESTIMATE)
        );
        let o = goal_options(&node, &goal("auto", CalibrateGoal::NOISE_STATED), noise())?;
        assert_eq!(
            (o.selection.as_str(), o.weighting),
            ("auto", calib::Noise::Stated)
        );
        let bad = goal_options(&node, &goal("all", 0), noise()).map(|_| ());
        let e = bad.expect_err("selection all");
        assert!(e.to_string().contains("expected map, auto"), "{e}");
        assert_eq!(crate::error::exit_code(&e), 2);
        let e = goal_options(&node, &goal("", 7), noise())
            .map(|_| ())
            .expect_err("noise 7");
        assert!(e.to_string().contains("found 7"), "{e}");
        Ok(())
    }

    #[test]
    fn poses_without_a_measurement_are_not_kept() -> anyhow::Result<()> {
        let mut acc = Accumulator::new(8);
        for seq in 1..=1000u64 {
            let s = ActuatorState {
                seq,
                stamp: rpkm_msgs::Time {
                    sec: 1,
                    nanosec: u32::try_from(seq).expect("seq <= 1000"),
                },
                ..Default::default()
            };
            acc.state(&s);
            let m = TcpMeasurement {
                stamp: s.stamp,
                setup: "stream".into(),
                instrument: TcpMeasurement::NONE,
                ..Default::default()
            };
            assert!(acc.measurement(&m)?);
        }
        assert_eq!((acc.measurements, acc.unmeasured), (0, 1000));
        Ok(())
    }

    #[test]
    fn messages_rebuild_the_campaign_and_calibrate_like_the_core() -> anyhow::Result<()> {
        // a noisy twin: the diagnosis estimates its noise and tries every effect
        let mut twin = Twin::new(TwinConfig::default())?;
        let c = twin.campaign_by_names(&["lt", "validation"], 20)?;
        let mut acc = Accumulator::new(8);
        for (i, pose) in c.poses.iter().enumerate() {
            let (s, m) = pose_messages(&c, i, pose)?;
            acc.state(&s);
            assert!(acc.measurement(&m)?);
        }
        let (rebuilt, stated) = acc.take()?;
        // The messages carry the spec's σ of each instrument: read back, it is the default.
        assert_eq!(stated, rpkm_core::noise::NoiseModel::default());
        let o = CalibratorOptions {
            start: nominal_start(),
            validation_prefix: "val".into(),
            selection: "map".into(),
            max_condition: 100.0,
            outlier_sigma: 0.0,
            noise: stated,
            effects: None,
            weighting: calib::Noise::ESTIMATE,
        };
        let out = calibrate_campaign(&rebuilt, &o)?;
        // Independent truth: the core on the original campaign without its held-out setup.
        let (cal_part, _) = split(&c, "val");
        let opts = Options {
            outlier_sigma: None,
            ..Options::default()
        };
        let nominal = Params::nominal();
        let (direct, _) = calib::calibrate(&calib::Request {
            noise: calib::Noise::ESTIMATE,
            ..calib::Request::new(&cal_part, &nominal, &opts)
        })?;
        for (name, v) in out.parameters.names.iter().zip(&out.parameters.values) {
            let i = rpkm_core::params::index_of(name)
                .ok_or("name")
                .map_err(anyhow::Error::msg)?;
            let expect = direct.params[i]
                / if rpkm_core::params::unit(i) == rpkm_core::params::Unit::Mm {
                    MM_PER_M
                } else {
                    1.0
                };
            assert!((v - expect).abs() < 1e-9, "{name}: {v} vs {expect}");
        }
        assert_eq!(out.parameters.model, 29);
        // The measurements of the calibration part (the held-out setup excluded), not the
        // fit's rows (x and y of a tracker pose are two).
        assert_eq!(
            out.parameters.measurement_count as usize,
            cal_part.poses.len()
        );
        assert!(direct.rows > cal_part.poses.len(), "rows {}", direct.rows);
        assert!(out.parameters.val_rms.is_finite());
        // the tracker's noise (5 µm along the beam, 25-30 µm across) sets the held-out RMS
        assert!(
            out.parameters.val_rms < 40e-6,
            "held-out {} m",
            out.parameters.val_rms
        );
        let d = out
            .diagnosis
            .ok_or_else(|| anyhow::anyhow!("not diagnosed"))?
            .map_err(anyhow::Error::msg)?;
        assert_eq!(d.missing_effect, "", "an effect-free twin misses no effect");
        assert!(!d.candidates.is_empty());
        Ok(())
    }

    /// While a tie is open the periodic /diagnostics values say which two and how far the
    /// evidence has come; once settled they say nothing of it.
    #[test]
    fn an_open_tie_is_on_the_periodic_status() {
        use rpkm_core::calib::tie::TieEvidence;
        use rpkm_core::params::{L1, L3};
        let mut c = Calibrator::new(16, None, None);
        let has = |c: &Calibrator, k: &str| {
            c.report_values()
                .into_iter()
                .find(|v| v.0 == k)
                .map(|v| v.1)
        };
        assert_eq!(has(&c, "online_tie"), None);
        c.tie = Some(TieSoFar {
            named: L3,
            runner_up: L1,
            evidence: TieEvidence {
                chi2: 12.84,
                ..TieEvidence::default()
            },
        });
        assert_eq!(has(&c, "online_tie").as_deref(), Some("l3 or l1"));
        assert_eq!(
            has(&c, "online_tie_evidence_chi2").as_deref(),
            Some("12.8 of 27.6")
        );
    }
}
