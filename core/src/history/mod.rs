//! A machine's history, the arithmetic: what changed between two calibrations and whether it
//! is real ([`change`]), and how each parameter moves over many ([`trend`]: a weighted line
//! with its significance, and when it leaves its tolerance). Pure: the calibrations come in
//! as [`Estimate`]s; where they are kept is the `rpkm-history` crate's business.
//!
//! A calibration under the tolerance prior (`calib::Selection::Prior`) reports every
//! parameter, but only those the campaign *determined* carry its information; the others sit
//! at the prior with the prior's σ. A parameter is determined by a calibration when its
//! posterior variance is below half the prior's: the data's information on it exceeds the
//! prior's, the one-parameter form of the count `Calibration::determined` makes over the
//! eigen-directions. A change or a trend is stated only over what both (or all) calibrations
//! determined; a change nobody could see is unknown, not zero.

mod change;
mod trend;

pub use change::{change, Change, Joint, ParamChange, Seen, FLAG_SIGMA};
pub use trend::{crossing, trend, Crossing, Point, Trend, LINE_P_VALUE, MIN_POINTS};

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
