//! A calibration job: the campaign split into fit and validation, the options, the calibration
//! run.

use super::diagnosis::{diagnose_model, diagnose_until, diagnosis_msg, Diagnosed};
use super::parameters::parameters_of;
use crate::error::bad_input;
use crate::node::geometry::Geometry;
use rpkm_core::calib::{
    self, Calibration, CommandCalibration, CommandError, CommandRequest, Options, Selection,
};
use rpkm_core::campaign::Campaign;
use rpkm_msgs::{Diagnosis, Parameters};

/// A finished calibration as messages.
#[derive(Debug, Clone)]
pub struct JobOutcome {
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
    /// Measurements held out for validation: the campaign's setups that start with the
    /// `validation_prefix`, or a validation campaign of the job's own.
    pub held_out: usize,
}

impl JobOutcome {
    /// `196 measurements (194 calibrated, 2 held out)`: the ones held out counted whether
    /// they came in the campaign or in a validation file.
    pub fn measurements_text(&self) -> String {
        let calibrated = self.campaign.poses.len();
        format!(
            "{} measurements ({calibrated} calibrated, {} held out)",
            calibrated + self.held_out,
            self.held_out
        )
    }
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

/// Which parameters the node's calibration identifies (parameter `selection`, a goal's).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SelectionRule {
    /// `map`: every parameter under its manufacturing tolerance, noise estimated from the
    /// campaign (what `rpkm calibrate` and `rpkm diagnose` do).
    Map,
    /// `auto`: the thesis's observability selection under `max_condition`.
    Auto,
}

impl SelectionRule {
    /// The rule a parameter or a goal names (`map`, `auto`).
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "map" => Some(Self::Map),
            "auto" => Some(Self::Auto),
            _ => None,
        }
    }

    /// As the parameter writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Map => "map",
            Self::Auto => "auto",
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
    /// Which parameters the calibration identifies.
    pub selection: SelectionRule,
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
pub(super) fn split(c: &Campaign, prefix: &str) -> (Campaign, Option<Campaign>) {
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

/// The calibration's options of the node's settings.
fn calibration_options(o: &CalibratorOptions) -> Options {
    let selection = match o.selection {
        SelectionRule::Map => Options::default().selection,
        SelectionRule::Auto => Selection::Auto {
            max_condition: o.max_condition,
        },
    };
    Options {
        model: o.start.model,
        selection,
        outlier_sigma: (o.outlier_sigma > 0.0).then_some(o.outlier_sigma),
        noise: o.noise.clone(),
        ..Default::default()
    }
}

/// Calibrates `campaign` (mm, rad) and builds the messages.
pub fn calibrate_campaign(
    campaign: &Campaign,
    o: &CalibratorOptions,
) -> anyhow::Result<JobOutcome> {
    calibrate_job(&Job::of(campaign), o)
}

/// Calibrates as `job` asks and builds the messages; a calibration its observer stopped is
/// the error `CalibrationError::Cancelled`.
pub fn calibrate_job(job: &Job, o: &CalibratorOptions) -> anyhow::Result<JobOutcome> {
    let (cal_part, own_val) = split(job.campaign, &o.validation_prefix);
    let val_part = job.validation.cloned().or(own_val);
    let opts = calibration_options(o);
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
    // the calibration every command shares, weighted as the node's settings say
    let CommandCalibration {
        effects: set,
        calibration: cal,
        noise,
    } = calib::calibrate_command(&CommandRequest {
        noise: o.weighting,
        progress: job.progress,
        ..CommandRequest::new(&cal_part, &o.start.params, &opts, &effects)
    })
    .map_err(|e| match e {
        CommandError::Effects(e) => bad_input(format!("{named_by}: {e}")),
        CommandError::Calibration(e) => anyhow::Error::new(e),
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
    let held_out = val_part.as_ref().map_or(0, |v| v.poses.len());
    Ok(JobOutcome {
        held_out,
        parameters,
        diagnosis,
        verdict,
        iterations: cal.iterations,
        noise,
        calibration: cal,
        campaign: cal_part,
    })
}
