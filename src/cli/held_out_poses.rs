//! The held-out residual pose by pose, as `--json` carries it (`held_out_poses`): what the
//! held-out judge judged and what its "follows" line summarises, for a user to plot over the
//! workspace or the campaign's time.

use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::held_out::poses::residuals;
use rpkm_core::diagnose::HeldOutCheck;
use serde_json::json;

/// Each held-out TCP reading of `val` with the judge's residual (µm, model − measured, each
/// setup's zero removed): its line, setup, instrument, time, coordinate, nominal TCP x and y
/// (mm) and covariates. Empty where the judge kept no residuals.
pub fn held_out_poses(val: &Campaign, judge: &HeldOutCheck) -> anyhow::Result<serde_json::Value> {
    let rows =
        residuals(val, judge).map_err(|e| super::bad_input(format!("{}: {e}", val.source)))?;
    let rows: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            let p = &val.poses[r.pose];
            let covariates: serde_json::Map<String, serde_json::Value> = val
                .covariate_names
                .iter()
                .zip(&p.covariates)
                .map(|(n, v)| (n.clone(), json!(v)))
                .collect();
            let mut row = json!(r);
            row["setup"] = json!(p.setup);
            row["instrument"] = json!(p.instrument.as_str());
            row["covariates"] = json!(covariates);
            row
        })
        .collect();
    Ok(json!(rows))
}

/// The held-out campaign's figures of a report (`out`): its coverage against the calibration
/// campaign's covariates, and each pose's residual where the judge (`judge`) kept them.
pub fn held_out_json(
    out: &mut serde_json::Map<String, serde_json::Value>,
    (campaign, held_out): (&Campaign, &Campaign),
    judge: Option<&HeldOutCheck>,
) -> anyhow::Result<()> {
    out.insert(
        "held_out_coverage".into(),
        serde_json::to_value(rpkm_core::diagnose::held_out::coverage::coverage(
            campaign, held_out,
        ))?,
    );
    if let Some(j) = judge {
        out.insert("held_out_poses".into(), held_out_poses(held_out, j)?);
    }
    Ok(())
}
