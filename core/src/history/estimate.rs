//! The history's vocabulary: one calibration as its arithmetic reads it. Below the files
//! that use it (`change`, `trend`'s callers), so the work flows one way.

use crate::params::{Model, Params, N_PARAMS};
use nalgebra::SMatrix;

/// One calibration as the history's arithmetic reads it.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// When it was made, s (any origin, the same for every estimate compared).
    pub t_s: f64,
    pub model: Model,
    /// The calibrated parameters (mm, rad).
    pub params: Params,
    /// Their posterior covariance (mm, rad): a parameter held at its start value has zero
    /// variance (`Calibration::covariance`).
    pub covariance: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// Each parameter's manufacturing tolerance, one σ (the prior's; mm, rad): the yardstick
    /// of "determined" and the band a trend leaves.
    pub tolerance: [f64; N_PARAMS],
}

impl Estimate {
    /// The σ of parameter `i` (mm, rad).
    pub fn sigma(&self, i: usize) -> f64 {
        self.covariance[(i, i)].max(0.0).sqrt()
    }

    /// Whether the calibration determined parameter `i`: in its model, identified (a
    /// variance), and known better than half its tolerance's variance.
    pub fn determined(&self, i: usize) -> bool {
        let v = self.covariance[(i, i)];
        let tol = self.tolerance[i];
        self.model.has_param(i) && v > 0.0 && v.is_finite() && v < 0.5 * tol * tol
    }
}
