//! The held-out judge's residual pose by pose: each held-out TCP reading with where and when
//! it was measured, for the JSON and the report's map and time plot of what the judge's
//! "follows" line summarises.

use crate::campaign::Campaign;
use crate::diagnose::structure::sparse::nominal_tcp;
use crate::diagnose::types::HeldOutCheck;
use crate::obs::{self, PoseError};
use crate::params::{Model, Params};

/// One held-out TCP reading's residual as the judge judged it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct HeldOutResidual {
    /// The pose's index in the held-out campaign, and its line in the file.
    pub pose: usize,
    pub line: usize,
    /// Time of the pose, s.
    pub t: f64,
    /// The coordinate: `x`, `y` or `r` (the ball-bar's distance).
    pub direction: &'static str,
    /// The pose's nominal TCP, mm.
    pub x_mm: f64,
    pub y_mm: f64,
    /// Model − measured, mm (µm in the JSON), its setup's zero removed.
    #[serde(
        rename = "residual_um",
        serialize_with = "crate::diagnose::types::as_um"
    )]
    pub residual: f64,
}

/// Each held-out TCP reading of `val` with the `judge`'s residual; empty where the judge
/// kept none (its readings are those of [`obs::tcp_errors`], in that order).
pub fn residuals(val: &Campaign, judge: &HeldOutCheck) -> Result<Vec<HeldOutResidual>, PoseError> {
    // the same readings in the same order as the judge's errors (only the values differ)
    let readings = obs::tcp_errors(val, &Params::nominal(), Model::M29)?;
    if readings.len() != judge.figures.errors.relative.len() {
        return Ok(Vec::new());
    }
    let tcp = nominal_tcp(val);
    Ok(readings
        .iter()
        .zip(&judge.figures.errors.relative)
        .map(|(r, e)| HeldOutResidual {
            pose: r.pose,
            line: val.poses[r.pose].line,
            t: val.poses[r.pose].t,
            direction: r.direction.as_str(),
            x_mm: tcp[r.pose].0,
            y_mm: tcp[r.pose].1,
            residual: *e,
        })
        .collect())
}
