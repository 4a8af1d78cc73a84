//! Levenberg-Marquardt with Nielsen's damping update (Madsen, Nielsen, Tingleff 2004), on the
//! scaled variables δ = H⁻¹ Δp_red (eq. 3.24), with the tolerance prior as pseudo-rows.
//!
//! Termination as MINPACK's `lmder` states it (Moré, Garbow, Hillstrom 1980):
//! - `ftol`: both the actual and the predicted relative reduction of the cost of an accepted
//!   step are at most [`FTOL`];
//! - `gtol`: the cosine of the angle between the residual vector and every column of the
//!   Jacobian is at most [`GTOL`] (the gradient vanishes relative to the problem's scale);
//! - `xtol`: the step, in the scaled variables, is at most [`XTOL`] times the scaled distance
//!   travelled from the start (plus `XTOL`).
//!
//! A nearly linear problem (calibration from nominal parameters) stops after a few steps: the
//! first is almost a Gauss-Newton step (see [`TAU`]).

/// Relative cost reduction below which the fit has converged. MINPACK's default is √ε ≈
/// 1.5e-8; χ² to 1e-10 relative is finer than any test of the diagnosis needs.
pub const FTOL: f64 = 1e-10;
/// Cosine between the residual and each Jacobian column below which the gradient vanishes.
pub const GTOL: f64 = 1e-10;
/// Relative step below which the unknowns no longer move.
pub const XTOL: f64 = 1e-10;
/// Initial damping relative to the largest diagonal of JᵀJ. Madsen, Nielsen and Tingleff
/// advise 1e-6 or less when the start is close to the solution: a calibration starts from
/// nominal parameters, within manufacturing tolerance of the truth, where the rows are nearly
/// linear in the unknowns, so the first step is close to Gauss-Newton. The damping grows by
/// itself where a step fails. Measured on the foreign campaigns: 3-4 iterations where 1e-3
/// took 12-15 (the damping then decays by 3 per step over the problem's six decades of
/// eigenvalues), with χ² equal to 1e-8 relative.
pub const TAU: f64 = 1e-9;

use super::rows::{weighted_jacobian, weighted_theta, weighted_values, Key, Problem};
use super::CalibrationError;
use crate::obs::{PoseError, Step};
use crate::params::{Params, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::HashSet;

/// The unknowns of a calibration: geometric parameters and effect parameters.
#[derive(Clone, Debug)]
pub(super) struct State {
    pub p: Params,
    pub theta: Vec<f64>,
}

/// One least-squares problem of a step: which rows, which unknowns, how they are scaled.
pub(super) struct Lm<'a> {
    pub problem: &'a Problem<'a>,
    pub step: Step,
    /// The parameters the step's virtual measurements are made with.
    pub p_cal: Params,
    pub drop: &'a HashSet<Key>,
    /// Dependency matrix (29 × n) and scaling (n) of the identified geometric parameters.
    pub d: DMatrix<f64>,
    pub h: DVector<f64>,
    /// The identified effect parameters and their scaling.
    pub free_theta: &'a [usize],
    pub h_theta: DVector<f64>,
    pub max_iterations: usize,
    /// Per reduced parameter: its index and tolerance (empty: no prior), and the prior's
    /// centre.
    pub prior: Vec<(usize, f64)>,
    pub center: Params,
}

/// The solver's state between iterations, allocated once per run: the stacked weighted
/// residual and Jacobian of the accepted point, its normal matrix and gradient, the damped
/// matrix, and the same for the trial point.
struct Buffers {
    r: DVector<f64>,
    js: DMatrix<f64>,
    a: DMatrix<f64>,
    g: DVector<f64>,
    damped: DMatrix<f64>,
    r_trial: DVector<f64>,
    js_trial: DMatrix<f64>,
}

impl Buffers {
    /// Buffers for `cols` unknowns (the rows are sized at the first evaluation).
    fn new(cols: usize) -> Buffers {
        Buffers {
            r: DVector::zeros(0),
            js: DMatrix::zeros(0, cols),
            a: DMatrix::zeros(cols, cols),
            g: DVector::zeros(cols),
            damped: DMatrix::zeros(cols, cols),
            r_trial: DVector::zeros(0),
            js_trial: DMatrix::zeros(0, cols),
        }
    }
}

/// What a converged run found.
pub(super) struct LmResult {
    pub state: State,
    pub iterations: usize,
}

impl Lm<'_> {
    fn n_unknowns(&self) -> usize {
        self.h.len() + self.free_theta.len()
    }

    /// Weighted residuals and scaled Jacobian at `x` written into `r` and `js` (resized when
    /// the number of rows changes: a step that changes which rows exist).
    fn eval_into(
        &self,
        x: &State,
        r: &mut DVector<f64>,
        js: &mut DMatrix<f64>,
    ) -> Result<(), PoseError> {
        let pb = self.problem;
        let corr = pb.effects.corrections(&x.theta);
        let rows = pb.rows(self.step, &x.p, &self.p_cal, &corr, self.drop)?;
        let (m, n, np) = (rows.len(), self.h.len(), self.prior.len());
        let cols = self.n_unknowns();
        if r.len() != m + np || js.shape() != (m + np, cols) {
            *r = DVector::zeros(m + np);
            *js = DMatrix::zeros(m + np, cols);
        }
        r.rows_mut(0, m).copy_from(&weighted_values(&rows));
        let mut jg = weighted_jacobian(&rows) * &self.d;
        for k in 0..n {
            jg.column_mut(k).scale_mut(self.h[k]);
        }
        js.view_mut((0, 0), (m, n)).copy_from(&jg);
        let mut jt = weighted_theta(&rows, self.free_theta);
        for k in 0..self.free_theta.len() {
            jt.column_mut(k).scale_mut(self.h_theta[k]);
        }
        js.view_mut((0, n), (m, jt.ncols())).copy_from(&jt);
        // the prior as pseudo-rows (p − centre)/tolerance below the measurements
        js.rows_mut(m, np).fill(0.0);
        for (k, &(i, tol)) in self.prior.iter().enumerate() {
            r[m + k] = (x.p[i] - self.center[i]) / tol;
            js[(m + k, k)] = self.h[k] / tol;
        }
        Ok(())
    }

    fn apply(&self, x: &State, delta: &DVector<f64>) -> State {
        let n = self.h.len();
        let dp = &self.d * delta.rows(0, n).component_mul(&self.h);
        let mut out = x.clone();
        for i in 0..N_PARAMS {
            out.p[i] += dp[i];
        }
        for (k, &t) in self.free_theta.iter().enumerate() {
            out.theta[t] += delta[n + k] * self.h_theta[k];
        }
        out
    }

    /// Normal matrix and gradient of the accepted point.
    fn normal_equations(b: &mut Buffers) {
        b.js.tr_mul_to(&b.js, &mut b.a);
        b.js.tr_mul_to(&b.r, &mut b.g);
    }

    /// MINPACK's gnorm: the largest |cos| between the residual vector and a Jacobian column
    /// (aᵢᵢ = ‖column i‖², gᵢ = column i · r).
    fn gradient_cosine(b: &Buffers) -> f64 {
        let rn = b.r.norm();
        if rn == 0.0 {
            return 0.0;
        }
        (0..b.g.len())
            .map(|i| {
                let cn = b.a[(i, i)].sqrt();
                if cn > 0.0 {
                    (b.g[i] / (cn * rn)).abs()
                } else {
                    0.0
                }
            })
            .fold(0.0, f64::max)
    }

    pub fn run(&self, start: &State) -> Result<LmResult, CalibrationError> {
        let cols = self.n_unknowns();
        let mut b = Buffers::new(cols);
        let mut p = start.clone();
        self.eval_into(&p, &mut b.r, &mut b.js)?;
        Self::normal_equations(&mut b);
        let mut cost = 0.5 * b.r.norm_squared();
        let mut mu = TAU * b.a.diagonal().max();
        let mut nu = 2.0;
        let done = |state: State, iterations: usize| Ok(LmResult { state, iterations });
        // distance travelled from the start in the scaled variables (for xtol)
        let mut travelled = DVector::<f64>::zeros(cols);
        for it in 0..self.max_iterations {
            if Self::gradient_cosine(&b) <= GTOL {
                return done(p, it);
            }
            b.damped.copy_from(&b.a);
            for k in 0..cols {
                b.damped[(k, k)] += mu;
            }
            let Some(chol) = b.damped.clone().cholesky() else {
                mu *= nu;
                nu *= 2.0;
                continue;
            };
            let step = -chol.solve(&b.g);
            let candidate = self.apply(&p, &step);
            let predicted = 0.5 * step.dot(&(step.scale(mu) - &b.g));
            let cost2 = self
                .eval_into(&candidate, &mut b.r_trial, &mut b.js_trial)
                .ok()
                .map(|()| 0.5 * b.r_trial.norm_squared());
            match cost2 {
                Some(cost2) if cost2 < cost && predicted > 0.0 => {
                    let rho = (cost - cost2) / predicted;
                    let (actual_rel, predicted_rel) = ((cost - cost2) / cost, predicted / cost);
                    travelled += &step;
                    p = candidate;
                    std::mem::swap(&mut b.r, &mut b.r_trial);
                    std::mem::swap(&mut b.js, &mut b.js_trial);
                    Self::normal_equations(&mut b);
                    cost = cost2;
                    mu *= f64::max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0).powi(3));
                    nu = 2.0;
                    let ftol = actual_rel <= FTOL && predicted_rel <= FTOL && rho <= 2.0;
                    let xtol = step.norm() <= XTOL * (travelled.norm() + XTOL);
                    if ftol || xtol || cost == 0.0 {
                        return done(p, it + 1);
                    }
                }
                _ => {
                    // MINPACK applies ftol to a refused step too: a cost that no longer moves
                    // beyond round-off, and a model that predicts no more, is the minimum
                    if let Some(cost2) = cost2 {
                        if ((cost - cost2) / cost).abs() <= FTOL && predicted / cost <= FTOL {
                            return done(p, it + 1);
                        }
                    }
                    // a step that raises the cost or leaves the assembly mode is refused
                    mu *= nu;
                    nu *= 2.0;
                    if mu > 1e30 {
                        // no step lowers the cost: a minimum to machine precision, unless
                        // the gradient says otherwise
                        if b.g.amax() < 1e-3 * (1.0 + cost) {
                            return done(p, it + 1);
                        }
                        return Err(self.not_converged(it + 1, cost, &b));
                    }
                }
            }
        }
        Err(self.not_converged(self.max_iterations, cost, &b))
    }

    fn not_converged(&self, iterations: usize, cost: f64, b: &Buffers) -> CalibrationError {
        CalibrationError::NotConverged {
            iterations,
            cost,
            gradient: b.g.amax(),
        }
    }
}
