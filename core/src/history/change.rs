//! What changed between two calibrations of one machine, and whether it is real: each
//! parameter's change with the σ of both covariances (the calibrations are independent
//! measurements, so their variances add), flagged beyond [`FLAG_SIGMA`] where both determined
//! the parameter, unknown where either did not; and one χ² over every direction both
//! determined, the answer to "did anything change at all" that 29 separate tests cannot give
//! without a false alarm now and then; and the largest single change read as the largest of
//! the many tested (how often noise alone makes the largest of that many |z| this large), so
//! that a 3.1σ among 29 is told apart from a 3.1σ alone, and one large change the χ² spreads
//! over all its directions is still seen. [`Change::verdict`] reads the two together.

use super::estimate::Estimate;
use crate::params::N_PARAMS;
use crate::stats::{chi2_upper_tail, normal_upper_tail};
use nalgebra::DMatrix;

/// A change beyond this many σ is flagged.
pub const FLAG_SIGMA: f64 = 3.0;

/// Which of the two calibrations determined a parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Seen {
    Both,
    /// Only the earlier one.
    Before,
    /// Only the later one.
    After,
    Neither,
}

/// One parameter's change from `before` to `after`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ParamChange {
    pub param: usize,
    /// after − before (mm, rad).
    pub change: f64,
    /// √(σ_before² + σ_after²) (mm, rad).
    pub sigma: f64,
    pub seen: Seen,
}

impl ParamChange {
    /// The change in σ, where both calibrations determined the parameter (else unknown).
    pub fn z(&self) -> Option<f64> {
        (self.seen == Seen::Both && self.sigma > 0.0).then(|| self.change / self.sigma)
    }

    /// Whether the change is real: both determined it and it exceeds [`FLAG_SIGMA`].
    pub fn flagged(&self) -> bool {
        self.z().is_some_and(|z| z.abs() > FLAG_SIGMA)
    }
}

/// The change over every direction both calibrations determined, as one test.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Joint {
    /// Independent directions tested (the rank of the change's covariance over the
    /// parameters both determined).
    pub directions: usize,
    /// Δᵀ C⁺ Δ over them.
    pub chi2: f64,
    /// P(χ² ≥ this | nothing changed).
    pub p_value: f64,
}

/// A change is real when noise alone gives one this large less often than this (the joint
/// χ², or the largest single change among those tested).
pub const CHANGE_P_VALUE: f64 = 1e-3;

/// The largest single change in σ among the parameters both calibrations determined, read
/// as the largest of that many: a multiple comparison (Šidák: the changes taken as
/// independent).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LargestChange {
    pub param: usize,
    /// Its change in σ (signed).
    pub z: f64,
    /// The changes it is the largest of: the parameters both determined.
    pub among: usize,
    /// P(|z| ≥ this) for one parameter alone (two-sided).
    pub p_single: f64,
    /// P(the largest of `among` |z| ≥ this | nothing changed) = 1 − (1 − `p_single`)^`among`.
    pub p_largest: f64,
}

/// What the joint χ² and the largest single change say together.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ChangeVerdict {
    /// The joint χ² is beyond noise (p below [`CHANGE_P_VALUE`]).
    Changed,
    /// The joint χ² is not, but the largest single change is, even as the largest of many:
    /// one parameter moved (the χ² spreads it over every direction).
    OneChanged,
    /// Neither: what moved is what noise gives among this many parameters.
    NoChange,
}

/// The change between two calibrations, parameter by parameter and as a whole.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Change {
    /// Every parameter of either model, in parameter order.
    pub params: Vec<ParamChange>,
    /// None when the two share no determined parameter.
    pub joint: Option<Joint>,
    /// None when the two share no determined parameter.
    pub largest: Option<LargestChange>,
}

impl Change {
    /// The flagged parameters, the largest change in σ first.
    pub fn flagged(&self) -> Vec<ParamChange> {
        let mut f: Vec<ParamChange> = self
            .params
            .iter()
            .copied()
            .filter(ParamChange::flagged)
            .collect();
        f.sort_by(|a, b| {
            let z = |p: &ParamChange| p.z().map_or(0.0, f64::abs);
            z(b).total_cmp(&z(a))
        });
        f
    }

    /// The joint test and the largest single change read together; None when the two
    /// calibrations share no determined parameter.
    pub fn verdict(&self) -> Option<ChangeVerdict> {
        let largest = self.largest?;
        Some(if self.joint.is_some_and(|j| j.p_value < CHANGE_P_VALUE) {
            ChangeVerdict::Changed
        } else if largest.p_largest < CHANGE_P_VALUE {
            ChangeVerdict::OneChanged
        } else {
            ChangeVerdict::NoChange
        })
    }
}

/// The largest |z| of `params` where both determined the parameter, as the largest of them.
fn largest(params: &[ParamChange]) -> Option<LargestChange> {
    let zs: Vec<(usize, f64)> = params
        .iter()
        .filter_map(|p| p.z().map(|z| (p.param, z)))
        .collect();
    let &(param, z) = zs.iter().max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
    let p_single = 2.0 * normal_upper_tail(z.abs());
    // 1 − (1 − p)^n without losing a small p to rounding
    let n = zs.len() as f64;
    let p_largest = -(n * (-p_single).ln_1p()).exp_m1();
    Some(LargestChange {
        param,
        z,
        among: zs.len(),
        p_single,
        p_largest,
    })
}

/// What changed from `before` to `after`.
pub fn change(before: &Estimate, after: &Estimate) -> Change {
    let params: Vec<ParamChange> = (0..N_PARAMS)
        .filter(|&i| before.model.has_param(i) || after.model.has_param(i))
        .map(|i| ParamChange {
            param: i,
            change: after.params[i] - before.params[i],
            sigma: (before.covariance[(i, i)].max(0.0) + after.covariance[(i, i)].max(0.0)).sqrt(),
            seen: match (before.determined(i), after.determined(i)) {
                (true, true) => Seen::Both,
                (true, false) => Seen::Before,
                (false, true) => Seen::After,
                (false, false) => Seen::Neither,
            },
        })
        .collect();
    let both: Vec<usize> = params
        .iter()
        .filter(|p| p.seen == Seen::Both)
        .map(|p| p.param)
        .collect();
    let joint = joint(before, after, &both);
    let largest = largest(&params);
    Change {
        params,
        joint,
        largest,
    }
}

/// Relative size below which an eigenvalue of the change's covariance is round-off: a
/// direction both calibrations pinned exactly (a link) or not at all carries no test.
const RANK_TOLERANCE: f64 = 1e-10;

/// The χ² of the change over the parameters `both` determined, in units of the tolerance (so
/// that mm and rad weigh alike in the rank decision), with the pseudo-inverse of its
/// covariance.
fn joint(before: &Estimate, after: &Estimate, both: &[usize]) -> Option<Joint> {
    if both.is_empty() {
        return None;
    }
    let n = both.len();
    let tol = |k: usize| before.tolerance[both[k]];
    let c = DMatrix::from_fn(n, n, |r, s| {
        let (i, j) = (both[r], both[s]);
        (before.covariance[(i, j)] + after.covariance[(i, j)]) / (tol(r) * tol(s))
    });
    let d = DMatrix::from_fn(n, 1, |r, _| {
        (after.params[both[r]] - before.params[both[r]]) / tol(r)
    });
    let eig = c.symmetric_eigen();
    let top = eig.eigenvalues.max();
    let (mut chi2, mut directions) = (0.0, 0);
    for (k, &lambda) in eig.eigenvalues.iter().enumerate() {
        if lambda > RANK_TOLERANCE * top {
            let along = eig.eigenvectors.column(k).dot(&d.column(0));
            chi2 += along * along / lambda;
            directions += 1;
        }
    }
    (directions > 0 && chi2.is_finite()).then(|| Joint {
        directions,
        chi2,
        p_value: chi2_upper_tail(chi2, directions as f64),
    })
}
