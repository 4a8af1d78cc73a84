//! The held-out residual pose by pose, as `--json` carries it (`held_out_poses`): what the
//! held-out judge judged and what its "follows" line summarises, for a user to plot over the
//! workspace or the campaign's time.

use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::sparse::nominal_tcp;
use rpkm_core::diagnose::HeldOutCheck;
use rpkm_core::obs;
use rpkm_core::params::{Model, Params};
use serde_json::json;

/// Each held-out TCP reading of `val` with the judge's residual (µm, model − measured, each
/// setup's zero removed): its line, setup, time, coordinate, nominal TCP x and y (mm) and
/// covariates. Empty where the judge kept no residuals.
pub fn held_out_poses(val: &Campaign, judge: &HeldOutCheck) -> anyhow::Result<serde_json::Value> {
    // the same readings in the same order as the judge's errors (only the values differ)
    let readings = obs::tcp_errors(val, &Params::nominal(), Model::M29)
        .map_err(|e| super::bad_input(format!("{}: {e}", val.source)))?;
    if readings.len() != judge.errors_relative.len() {
        return Ok(json!([]));
    }
    let tcp = nominal_tcp(val);
    let rows: Vec<serde_json::Value> = readings
        .iter()
        .zip(&judge.errors_relative)
        .map(|(r, e)| {
            let p = &val.poses[r.pose];
            let covariates: serde_json::Map<String, serde_json::Value> = val
                .covariate_names
                .iter()
                .zip(&p.covariates)
                .map(|(n, v)| (n.clone(), json!(v)))
                .collect();
            json!({
                "line": p.line,
                "setup": p.setup,
                "instrument": p.instrument.as_str(),
                "t": p.t,
                "direction": r.direction.as_str(),
                "x_mm": tcp[r.pose].0,
                "y_mm": tcp[r.pose].1,
                "covariates": covariates,
                "residual_um": e * 1e3,
            })
        })
        .collect();
    Ok(json!(rows))
}
