//! What a plan buys, in the units the user judges a calibration by: the held-out RMS it
//! should give, defined as the diagnosis defines its held-out RMS with each setup's zero
//! removed (`val_rms_relative_um`: every TCP error of a held-out tracker setup, model minus
//! reading, less the mean of its setup and coordinate; `diagnose::HeldOutErrors` gives the
//! errors and their RMS). Its expectation over the parameters' uncertainty and the readings' noise is
//!
//! E[RMS²] = tr(A C) + floor²,
//!
//! C the unknowns' posterior covariance (tolerance units), A the mean over the held-out values
//! of ā āᵀ (ā: the TCP coordinate's sensitivity to the unknowns, less its mean over the
//! setup: the zero removed takes a rigid shift with it), floor² the mean variance the readings'
//! noise leaves once each setup's zero is removed (the diagnosis's `noise_floor_relative_um`).
//! The held-out setup is one tracker setup over the evaluation poses (the workspace grid or
//! the poses the user gives).

use super::types::{PlanError, Unknowns};
use crate::geometry::{self, Subsystem, X, Y};
use crate::noise::{NoiseModel, XyInstrument};
use crate::params::{Model, Params};
use nalgebra::{DMatrix, DVector, Vector2};

/// Where the TCP must be right, and what a held-out tracker setup there would read.
#[derive(Clone, Debug)]
pub struct TargetForecast {
    /// The held-out targets (x, y), mm.
    pub targets: Vec<(f64, f64)>,
    /// A: the mean of ā āᵀ over the held-out values (tolerance units, mm²).
    weight: DMatrix<f64>,
    /// RMS the tracker's noise alone leaves on the held-out errors, each setup's zero
    /// removed, mm.
    pub floor_mm: f64,
}

impl TargetForecast {
    /// The held-out setup over `targets` on a machine at `p` (the calibrated parameters),
    /// its readings' noise `noise`, for `unknowns`.
    pub fn new(
        targets: Vec<(f64, f64)>,
        p: &Params,
        (model, noise): (Model, &NoiseModel),
        unknowns: &Unknowns,
    ) -> Result<TargetForecast, PlanError> {
        if targets.is_empty() {
            return Err(PlanError::NoEvaluationPoses);
        }
        let n = unknowns.len();
        let mut rows: [Vec<DVector<f64>>; 2] = [Vec::new(), Vec::new()];
        let mut variance: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
        for &(x, y) in &targets {
            let at = |error| PlanError::Target { x, y, error };
            let q = geometry::igm(p, model, x, y).map_err(at)?.q();
            let sol = geometry::fgm(p, model, q[0], q[3]).map_err(at)?;
            let sens = geometry::sensitivity(p, model, Subsystem::NR, &sol).map_err(at)?;
            let cov = noise.xy_covariance(XyInstrument::Lt, Vector2::new(sol.x(), sol.y()));
            for (c, v) in [X, Y].into_iter().enumerate() {
                rows[c].push(DVector::from_fn(n, |k, _| {
                    sens.dc_dp[(v, unknowns.ids[k])] * unknowns.tolerance[k]
                }));
                variance[c].push(cov[(c, c)] + noise.encoder_mm.powi(2));
            }
        }
        let values = (2 * targets.len()) as f64;
        let mut weight = DMatrix::zeros(n, n);
        for coordinate in &rows {
            let mean = coordinate.iter().sum::<DVector<f64>>() / coordinate.len() as f64;
            for a in coordinate {
                let d = a - &mean;
                weight += &d * d.transpose() / values;
            }
        }
        let floor2: f64 = variance.iter().map(|v| relative_variance_sum(v)).sum();
        Ok(TargetForecast {
            targets,
            weight,
            floor_mm: (floor2 / values).sqrt(),
        })
    }

    /// The workspace's 231-point grid ([`crate::design::grid_231`]).
    pub fn grid(
        p: &Params,
        at: (Model, &NoiseModel),
        unknowns: &Unknowns,
    ) -> Result<TargetForecast, PlanError> {
        TargetForecast::new(crate::design::grid_231(), p, at, unknowns)
    }

    /// tr(A C): the mean square the parameters' uncertainty `c` (tolerance units) leaves on
    /// the held-out errors, mm².
    pub fn prediction_variance(&self, c: &DMatrix<f64>) -> f64 {
        self.weight.component_mul(c).sum()
    }

    /// The expected held-out RMS (mm), each setup's zero removed, with the unknowns'
    /// posterior covariance `c`.
    pub fn rms(&self, c: &DMatrix<f64>) -> f64 {
        (self.prediction_variance(c).max(0.0) + self.floor_mm.powi(2)).sqrt()
    }

    /// [`Self::rms`] of information `g` (tolerance units) under the tolerance prior:
    /// C = (I + G)⁻¹.
    pub fn rms_of_information(&self, g: &DMatrix<f64>) -> f64 {
        self.rms(&posterior(g))
    }

    /// A (read by the planner's criterion).
    pub(super) fn weight(&self) -> &DMatrix<f64> {
        &self.weight
    }
}

/// The TCP targets of `campaign`'s poses: where the machine at `p` stands at each pose's
/// (q1, q4) (a recorded production path as the poses to judge the TCP at).
pub fn targets_of(
    campaign: &crate::campaign::Campaign,
    p: &Params,
    model: Model,
) -> Result<Vec<(f64, f64)>, PlanError> {
    campaign
        .poses
        .iter()
        .map(|pose| {
            geometry::fgm(p, model, pose.q[0], pose.q[3])
                .map(|s| (s.x(), s.y()))
                .map_err(|e| PlanError::Rows(crate::obs::PoseError::at(campaign, pose, e)))
        })
        .collect()
}

/// (I + G)⁻¹ of a symmetric G ⪰ 0, symmetrised (its round-off), by its eigen-decomposition
/// where the Cholesky factor fails.
pub fn posterior(g: &DMatrix<f64>) -> DMatrix<f64> {
    let n = g.nrows();
    let m = (g + g.transpose()) * 0.5 + DMatrix::identity(n, n);
    if let Some(c) = m.clone().cholesky() {
        return c.inverse();
    }
    let eig = m.symmetric_eigen();
    let inv = eig.eigenvalues.map(|v| 1.0 / v.max(1.0));
    &eig.eigenvectors * DMatrix::from_diagonal(&inv) * eig.eigenvectors.transpose()
}

/// Σ var(e_i − ē) over the errors of one setup and coordinate with variances `v`
/// ([`crate::obs::zero_removed_variance`] each, as the diagnosis's held-out floor).
fn relative_variance_sum(v: &[f64]) -> f64 {
    let n = v.len().max(1) as f64;
    let total: f64 = v.iter().sum();
    v.iter()
        .map(|&s| crate::obs::zero_removed_variance(s, total, n))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// n equal variances σ²: each error less the mean has σ² (1 − 1/n).
    #[test]
    fn the_zero_removed_takes_one_reading_of_n_with_it() {
        let s = relative_variance_sum(&[4.0; 5]);
        assert!((s - 5.0 * 4.0 * 0.8).abs() < 1e-12);
    }

    /// One unknown uncertain by its tolerance, the others known: the prediction variance is
    /// the mean square, over the held-out values, of its TCP sensitivity less its mean per
    /// coordinate (the zero removed takes a rigid shift with it), the sensitivities taken
    /// here by finite differences of the forward model.
    #[test]
    fn prediction_variance_is_the_mean_square_of_the_centred_sensitivities() {
        let p = Params::nominal();
        let noise = NoiseModel::default();
        let unknowns = Unknowns::of_model(Model::M29, |_| 0.1);
        let targets = vec![(0.0, 1000.0), (100.0, 1700.0), (-120.0, 2500.0)];
        let e = TargetForecast::new(targets.clone(), &p, (Model::M29, &noise), &unknowns)
            .expect("reachable");
        // independent: finite differences of the TCP of each target's (q1, q4)
        let k = 3; // one parameter, its tolerance 0.1
        let i = unknowns.ids[k];
        let tcp = |p: &Params, (x, y): (f64, f64)| {
            let q = geometry::igm(&Params::nominal(), Model::M29, x, y)
                .expect("igm")
                .q();
            let s = geometry::fgm(p, Model::M29, q[0], q[3]).expect("fgm");
            [s.x(), s.y()]
        };
        let h = 1e-6;
        let mut shifted = p;
        shifted[i] += h;
        let d: Vec<[f64; 2]> = targets
            .iter()
            .map(|&t| {
                let (a, b) = (tcp(&p, t), tcp(&shifted, t));
                [(b[0] - a[0]) / h * 0.1, (b[1] - a[1]) / h * 0.1]
            })
            .collect();
        let mut want = 0.0;
        for c in 0..2 {
            let mean = d.iter().map(|v| v[c]).sum::<f64>() / 3.0;
            want += d.iter().map(|v| (v[c] - mean).powi(2)).sum::<f64>() / 6.0;
        }
        let mut c = DMatrix::zeros(unknowns.len(), unknowns.len());
        c[(k, k)] = 1.0;
        let got = e.prediction_variance(&c);
        assert!((got - want).abs() < 1e-6 * want.max(1e-12), "{got} {want}");
    }
}
