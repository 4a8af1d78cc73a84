//! What the data tell about the identified unknowns: posterior covariance under the prior,
//! the determined combinations, leverages, and step 2's uncertainty with step 1's propagated.

use super::rows::{reduced_jacobian, weighted_theta};
use super::{CalibrationError, Link};
use crate::obs::Residual;
use crate::params::{NAMES, N_PARAMS};
use nalgebra::{DMatrix, DVector};

/// What the final fit of step 1 tells about its unknowns (scaled by nothing: the caller
/// multiplies by the variance factor).
pub(super) struct Posterior {
    /// Covariance (JᵀJ + Λ)⁻¹ of the identified geometric parameters (Λ: the prior's
    /// precision, zero without one).
    pub cov1: DMatrix<f64>,
    /// Standard deviations of the free effect parameters.
    pub sig_theta: Vec<f64>,
    /// tr((JᵀJ + Λ)⁻¹ JᵀJ): the parameters the data determine.
    pub dof_model: f64,
    /// Diagonal of the hat matrix J (JᵀJ + Λ)⁻¹ Jᵀ, one per row.
    pub leverage: Vec<f64>,
    pub determined: Option<(usize, usize)>,
}

pub(super) fn posterior(
    rows: &[Residual],
    ids: &[usize],
    links: &[Link],
    free: &[usize],
    prior: &[(usize, f64)],
) -> Result<Posterior, CalibrationError> {
    let jg = reduced_jacobian(rows, ids, links);
    let jt = weighted_theta(rows, free);
    let n = ids.len();
    let mut jr = DMatrix::zeros(rows.len(), n + free.len());
    jr.columns_mut(0, n).copy_from(&jg);
    jr.columns_mut(n, free.len()).copy_from(&jt);
    let info = jr.transpose() * &jr;
    let inv = normal_inverse(&jr, ids, prior)?;
    let dof_model = (&inv * &info).trace();
    let leverage = (0..jr.nrows())
        .map(|i| {
            let j = jr.row(i);
            (j * &inv * j.transpose())[0]
        })
        .collect();
    // directions: eigenvalues of the data's information in units of the prior's
    let determined = (!prior.is_empty()).then(|| {
        let tol = DVector::from_iterator(n, prior.iter().map(|p| p.1));
        let g =
            DMatrix::from_diagonal(&tol) * info.view((0, 0), (n, n)) * DMatrix::from_diagonal(&tol);
        let ev = g.symmetric_eigenvalues();
        (ev.iter().filter(|&&v| v > 1.0).count(), n)
    });
    Ok(Posterior {
        cov1: inv.view((0, 0), (n, n)).into_owned(),
        sig_theta: (0..free.len())
            .map(|k| inv[(n + k, n + k)].max(0.0).sqrt())
            .collect(),
        dof_model,
        leverage,
        determined,
    })
}

/// (JᵀJ + Λ)⁻¹ with the prior's precision Λ on the first `prior.len()` columns.
fn normal_inverse(
    jr: &DMatrix<f64>,
    ids: &[usize],
    prior: &[(usize, f64)],
) -> Result<DMatrix<f64>, CalibrationError> {
    let mut n = jr.transpose() * jr;
    for (k, &(_, tol)) in prior.iter().enumerate() {
        n[(k, k)] += 1.0 / (tol * tol);
    }
    n.try_inverse().ok_or_else(|| {
        CalibrationError::Singular(ids.iter().map(|&i| NAMES[i]).collect::<Vec<_>>().join(", "))
    })
}

/// Uncertainty of the second step's parameters: the noise of its virtual rows plus the first
/// step's parameter uncertainty (`cov_p1`, 29 × 29), propagated linearly through the virtual
/// measurements (which share it, so it does not average out).
pub(super) fn step2_uncertainties(
    rows: &[Residual],
    ids: &[usize],
    prior: &[(usize, f64)],
    cov_p1: &DMatrix<f64>,
) -> Result<Vec<f64>, CalibrationError> {
    let jr = reduced_jacobian(rows, ids, &[]);
    let inv = normal_inverse(&jr, ids, prior)?;
    let m = &inv * jr.transpose();
    let g = DMatrix::from_fn(rows.len(), N_PARAMS, |i, k| {
        rows[i].d_pcal.map_or(0.0, |d| d[k]) / rows[i].sigma
    });
    let mg = &m * g;
    let cov = inv + &mg * cov_p1 * mg.transpose();
    Ok((0..ids.len())
        .map(|k| cov[(k, k)].max(0.0).sqrt())
        .collect())
}
