//! What the data tell about the identified unknowns: posterior covariance under the prior,
//! the determined combinations, leverages, and step 2's uncertainty with step 1's propagated.

use super::lm::Final;
use super::plan::Plan;
use super::rows::{reduced_jacobian, weighted_theta, Key, Problem};
use super::types::{CalibrationError, Link};
use crate::effects::Corrections;
use crate::obs::{Residual, RowValue, Step};
use crate::params::Params;
use crate::params::{NAMES, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::HashSet;

/// What the final fit of step 1 tells about its unknowns (scaled by nothing: the caller
/// multiplies by the variance factor).
pub(super) struct Posterior {
    /// Covariance (JᵀJ + Λ)⁻¹ of the identified geometric parameters (Λ: the prior's
    /// precision, zero without one).
    pub cov1: DMatrix<f64>,
    /// Standard deviations of the free effect parameters.
    pub sig_theta: Vec<f64>,
    /// Covariance of the free effect parameters with the identified geometric ones
    /// (`ids` × free) and among themselves (free × free).
    pub cov_cross: DMatrix<f64>,
    pub cov_theta: DMatrix<f64>,
    /// tr((JᵀJ + Λ)⁻¹ JᵀJ): the parameters the data determine.
    pub dof_model: f64,
    /// Diagonal of the hat matrix J (JᵀJ + Λ)⁻¹ Jᵀ, one per row.
    pub leverage: Vec<f64>,
    pub determined: Option<(usize, usize)>,
}

/// Rows per block of the sums below: the rows' Jacobian is never stored whole.
const BLOCK: usize = 512;

/// Campaigns up to this many poses keep their final rows' Jacobian between the information
/// and the leverages (at most a few rows per pose of 29 + k columns: 10-50 MB); larger ones
/// evaluate the rows once more for the leverages and hold one piece per thread.
pub(super) const KEEP_JACOBIAN_POSES: usize = 20_000;

/// The weighted Jacobian of a block of rows in the unknowns: parameters `ids` under links,
/// then the effect parameters `free`.
fn block_jacobian(
    rows: &[Residual],
    ids: &[usize],
    links: &[Link],
    free: &[usize],
) -> DMatrix<f64> {
    let n = ids.len();
    let mut jr = DMatrix::zeros(rows.len(), n + free.len());
    jr.columns_mut(0, n)
        .copy_from(&reduced_jacobian(rows, ids, links));
    jr.columns_mut(n, free.len())
        .copy_from(&weighted_theta(rows, free));
    jr
}

/// The final rows of step 1 at `p` (their values) and what they tell about the plan's
/// unknowns: the LM's last evaluation there (`last`: values and information); where
/// `leverages` asks for them, the leverages from its kept Jacobians or, for a large
/// campaign, one more pass over the rows (the effects' corrections at `p` then, from
/// `corr`: made only where needed), else none.
pub(super) fn posterior<'c>(
    pb: &Problem,
    plan: &Plan,
    (p, corr, drop): (&Params, &dyn Fn() -> &'c Corrections, &HashSet<Key>),
    (last, leverages): (Final, bool),
) -> Result<(Vec<RowValue>, Posterior), CalibrationError> {
    let (ids, links, free, prior) = (&plan.ids, &pb.opts.links, &plan.free_theta, &plan.prior);
    let n = ids.len();
    let info = last.info;
    let mut info_prior = info.clone();
    for &(f, sigma) in &plan.theta_prior {
        info_prior[(n + f, n + f)] += 1.0 / (sigma * sigma);
    }
    let inv = normal_inverse(&info_prior, ids, prior)?;
    let dof_model = (&inv * &info).trace();
    let leverage_of = |jr: &DMatrix<f64>, inv: &DMatrix<f64>| {
        let ji = jr * inv;
        (0..jr.nrows())
            .map(|i| ji.row(i).dot(&jr.row(i)))
            .collect::<Vec<f64>>()
    };
    let leverage = match last.jacobians {
        _ if !leverages => Vec::new(),
        Some(pieces) => pieces.iter().flat_map(|jr| leverage_of(jr, &inv)).collect(),
        None => pb
            .map_pieces(Step::Direct, p, &pb.start, corr(), drop, |rows| {
                leverage_of(&block_jacobian(rows, ids, links, free), &inv)
            })?
            .concat(),
    };
    // directions: eigenvalues of the data's information in units of the prior's
    let determined = (!prior.is_empty()).then(|| {
        let tol = DVector::from_iterator(n, prior.iter().map(|p| p.1));
        let g =
            DMatrix::from_diagonal(&tol) * info.view((0, 0), (n, n)) * DMatrix::from_diagonal(&tol);
        let ev = g.symmetric_eigenvalues();
        (ev.iter().filter(|&&v| v > 1.0).count(), n)
    });
    let post = Posterior {
        cov1: inv.view((0, 0), (n, n)).into_owned(),
        sig_theta: (0..free.len())
            .map(|k| inv[(n + k, n + k)].max(0.0).sqrt())
            .collect(),
        cov_cross: inv.view((0, n), (n, free.len())).into_owned(),
        cov_theta: inv.view((n, n), (free.len(), free.len())).into_owned(),
        dof_model,
        leverage,
        determined,
    };
    Ok((last.rows, post))
}

/// (JᵀJ + Λ)⁻¹ from the information JᵀJ, with the prior's precision Λ on the first
/// `prior.len()` columns.
fn normal_inverse(
    info: &DMatrix<f64>,
    ids: &[usize],
    prior: &[(usize, f64)],
) -> Result<DMatrix<f64>, CalibrationError> {
    let mut n = info.clone();
    for (k, &(_, tol)) in prior.iter().enumerate() {
        n[(k, k)] += 1.0 / (tol * tol);
    }
    n.try_inverse().ok_or_else(|| {
        CalibrationError::Singular(ids.iter().map(|&i| NAMES[i]).collect::<Vec<_>>().join(", "))
    })
}

/// Covariance of the second step's parameters: the noise of its virtual rows plus the first
/// step's parameter uncertainty (`cov_p1`, 29 × 29), propagated linearly through the virtual
/// measurements (which share it, so it does not average out). Returns that covariance
/// (`ids` × `ids`) and the covariance of step 2's parameters with the 29 of step 1 (`ids` ×
/// 29): a Gauss-Newton step δp2 = −(JᵀJ + Λ)⁻¹ Jᵀ G δp1 moves them with step 1's error.
pub(super) fn step2_covariance(
    rows: &[Residual],
    ids: &[usize],
    prior: &[(usize, f64)],
    cov_p1: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, DMatrix<f64>), CalibrationError> {
    let n = ids.len();
    let (mut info, mut jtg) = (DMatrix::zeros(n, n), DMatrix::zeros(n, N_PARAMS));
    for block in rows.chunks(BLOCK) {
        let jr = reduced_jacobian(block, ids, &[]);
        let g = DMatrix::from_fn(block.len(), N_PARAMS, |i, k| {
            block[i].d_pcal.as_ref().map_or(0.0, |d| d[k]) / block[i].sigma
        });
        info += jr.tr_mul(&jr);
        jtg += jr.tr_mul(&g);
    }
    let inv = normal_inverse(&info, ids, prior)?;
    let mg = &inv * jtg;
    let cross = -(&mg * cov_p1);
    let cov = inv + &mg * cov_p1 * mg.transpose();
    Ok((cov, cross))
}
