//! A Calibrate goal's options and its result.

use super::job::{CalibratorOptions, JobOutcome, SelectionRule};
use crate::error::bad_input;
use crate::node::calibrate_action::noise_si;
use rpkm_core::calib;
use rpkm_msgs::calibrate_action::{CalibrateGoal, CalibrateResult};

/// The node's options with a goal's over them: its selection, its noise weighting, and the
/// noise the campaign's measurements state.
pub(super) fn goal_options(
    o: &CalibratorOptions,
    goal: &CalibrateGoal,
    noise: rpkm_core::noise::NoiseModel,
) -> anyhow::Result<CalibratorOptions> {
    let selection = match goal.selection.as_str() {
        "" => o.selection,
        other => SelectionRule::parse(other).ok_or_else(|| {
            bad_input(format!(
                "selection: expected map, auto or empty (the node's), found {other:?}"
            ))
        })?,
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
pub(super) fn goal_result(o: &JobOutcome, status: &str) -> CalibrateResult {
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
