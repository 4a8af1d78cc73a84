//! The calibration as a Parameters message, its effects' values included.

use crate::error::bad_input;
use crate::node::geometry::parameters_msg;
use crate::units::m_from_mm;
use rpkm_core::calib::{self, Calibration};
use rpkm_core::campaign::Campaign;
use rpkm_core::effects::Effect;
use rpkm_core::obs;
use rpkm_core::params::N_PARAMS;
use rpkm_msgs::Parameters;

/// The Parameters message of a calibration of `cal_part` of the model with `effects` (bound
/// to it as `set`), its held-out RMS on `val_part` by the diagnosis's own held-out judge (the
/// effects' corrections in, setup-local parameters re-fitted on the held-out setups).
pub(super) fn parameters_of(
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
        m_from_mm((sum / rows as f64).sqrt())
    } else {
        f64::NAN
    };
    let cal_errors: Vec<f64> = obs::tcp_errors_with(
        cal_part,
        &cal.params,
        cal.model,
        &set.corrections(&cal.theta, &cal.params),
    )
    .map(|e| e.iter().map(|e| e.value).collect())
    .unwrap_or_default();
    msg.max_abs_residual = if cal_errors.is_empty() {
        f64::NAN
    } else {
        m_from_mm(cal_errors.iter().fold(0.0, |m: f64, e| m.max(e.abs())))
    };
    // the diagnosis's held-out judge: `rpkm diagnose` and `rpkm calibrate` report the same
    msg.val_rms = match val_part {
        Some(v) => {
            let alpha = rpkm_core::diagnose::DiagnosisOptions::default().alpha;
            let judge =
                rpkm_core::diagnose::judge_calibration(v, noise, (effects, set), cal, alpha)
                    .map_err(|e| bad_input(format!("held-out setups: {e}")))?;
            m_from_mm(judge.rms())
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
    for e in effects.iter().filter(|e| e.physical()) {
        if !msg.active_effects.contains(&e.effect) {
            msg.active_effects.push(e.effect.clone());
        }
        let to_si = crate::effects_file::si_per_unit(&e.unit);
        msg.effect_parameter_names
            .push(format!("{}.{}", e.effect, e.name));
        msg.effect_parameter_values.push(e.value * to_si);
    }
}
