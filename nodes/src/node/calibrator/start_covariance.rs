//! The start covariance of the online tracker, read from a geometry file's JSON.

use crate::calibration_file::{CalibrationFile, PosteriorCovariance};
use crate::error::bad_input;
use nalgebra::SMatrix;
use rpkm_core::calib;
use rpkm_core::params::N_PARAMS;
use std::path::Path;

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
    let file = CalibrationFile::read(Path::new(geometry_file))?;
    if let Some(cov) = &file.covariance {
        return covariance_of(geometry_file, cov);
    }
    let Some(identified) = &file.identified else {
        return Ok(tolerance);
    };
    let mut cov = tolerance;
    for (n, e) in identified.iter().enumerate() {
        match (e.index, e.sigma) {
            (i, Some(s)) if i < N_PARAMS && s.is_finite() && s > 0.0 => cov[(i, i)] = s * s,
            (i, s) => {
                return Err(bad_input(format!(
                    "{geometry_file}: identified[{n}]: expected an `index` below {N_PARAMS} \
                     and a positive finite `sigma`, found index {i}, sigma {s:?}"
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
    v: &PosteriorCovariance,
) -> anyhow::Result<SMatrix<f64, N_PARAMS, N_PARAMS>> {
    let bad = |what: String| bad_input(format!("{file}: covariance: {what}"));
    if v.names
        .iter()
        .map(String::as_str)
        .ne(rpkm_core::params::NAMES)
    {
        return Err(bad(format!(
            "expected `names` with the {N_PARAMS} parameters in the spec's order (l1, l4, ...)"
        )));
    }
    let rows = Some(&v.matrix)
        .filter(|r| r.len() == N_PARAMS)
        .ok_or_else(|| bad(format!("expected `matrix` with {N_PARAMS} rows")))?;
    let mut cov = SMatrix::<f64, N_PARAMS, N_PARAMS>::zeros();
    for (i, row) in rows.iter().enumerate() {
        let row = Some(row)
            .filter(|r| r.len() == N_PARAMS)
            .ok_or_else(|| bad(format!("matrix[{i}]: expected {N_PARAMS} numbers")))?;
        for (j, x) in row.iter().enumerate() {
            cov[(i, j)] = Some(*x).filter(|x| x.is_finite()).ok_or_else(|| {
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
