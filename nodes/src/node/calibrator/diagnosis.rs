//! The diagnosis of the calibrated model and its Diagnosis message.

use crate::units::m_from_mm;
use rpkm_core::calib::{self, Calibration};
use rpkm_core::campaign::Campaign;
use rpkm_core::effects::Effect;
use rpkm_msgs::{Diagnosis, DiagnosisCandidate};

/// What the node diagnoses: the calibrated campaign (the held-out part for its validation)
/// with the model it calibrated, its effects in the model.
#[derive(Clone, Copy)]
pub(super) struct Diagnosed<'a> {
    pub(super) campaign: &'a Campaign,
    pub(super) validation: Option<&'a Campaign>,
    pub(super) calibration: &'a Calibration,
    pub(super) effects: &'a [&'a dyn Effect],
    /// The stated noise the estimate starts from (as the calibration's).
    pub(super) noise: &'a rpkm_core::noise::NoiseModel,
}

/// The model diagnosis of `rpkm_core::diagnose` with the node's effects in the model: what
/// `rpkm diagnose --effects ...` says of the same campaign.
pub(super) fn diagnose_model(
    d: Diagnosed,
    stop: Option<calib::Stop>,
) -> Result<rpkm_core::diagnose::ModelDiagnosis, rpkm_core::diagnose::DiagnoseError> {
    let opts = rpkm_core::diagnose::DiagnosisOptions {
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
pub(super) fn diagnose_until(
    d: Diagnosed,
    cancelled: &dyn Fn() -> bool,
) -> Result<rpkm_core::diagnose::ModelDiagnosis, rpkm_core::diagnose::DiagnoseError> {
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
pub(super) fn diagnosis_msg(d: &rpkm_core::diagnose::ModelDiagnosis) -> Diagnosis {
    let m = |mm: Option<f64>| mm.map_or(f64::NAN, m_from_mm);
    let held = d.held_out.as_ref();
    Diagnosis {
        verdict_kind: serde_json::to_value(d.verdict_kind)
            .ok()
            .and_then(|v| v.as_str().map(str::to_owned))
            .unwrap_or_default(),
        verdict: crate::words::verdict(d),
        missing_effects: d.missing_effects.clone(),
        model_effects: d.model_effects.clone(),
        baseline_val_rms_relative: m(d.baseline.val_rms_relative),
        floor_relative: m(held.map(|h| h.floor_relative)),
        held_out_agrees: held.is_some_and(rpkm_core::diagnose::HeldOutCheck::agrees),
        missing_effect: d.missing_effect.clone().unwrap_or_default(),
        candidates: d
            .candidates
            .iter()
            .map(|c| DiagnosisCandidate {
                effect: c.effect.clone(),
                significant: c.significant,
                explained_fraction: c.explained_fraction,
                val_rms_before: m(c.val_rms_before),
                val_rms_after: m(c.val_rms_after),
            })
            .collect(),
        baseline_cal_rms: m(Some(d.baseline.cal_rms)),
        baseline_val_rms: m(d.baseline.val_rms),
        noise_floor: m(Some(d.baseline.noise_floor)),
    }
}
