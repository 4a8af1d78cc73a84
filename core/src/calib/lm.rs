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

/// Relative cost reduction below which the fit has converged: MINPACK's default, √ε ≈
/// 1.5e-8. The normal equations of a calibration carry six decades of eigenvalues, so below
/// this the steps only shuffle round-off (measured: χ² then moves by 1e-9 relative per
/// step for five more steps); χ² differences between models in the diagnosis are O(1) on
/// costs of 10²-10⁵, far above it.
pub const FTOL: f64 = 1.490_116_119_384_765_6e-8;
/// Cosine between the residual and each Jacobian column below which the gradient vanishes.
pub const GTOL: f64 = 1e-10;
/// Relative step below which the unknowns no longer move: MINPACK's default, √ε.
pub const XTOL: f64 = 1.490_116_119_384_765_6e-8;
/// Initial damping relative to the largest diagonal of JᵀJ. Madsen, Nielsen and Tingleff
/// advise 1e-6 or less when the start is close to the solution: a calibration starts from
/// nominal parameters, within manufacturing tolerance of the truth, where the rows are nearly
/// linear in the unknowns, so the first step is close to Gauss-Newton. The damping grows by
/// itself where a step fails. Measured on the foreign campaigns: 3-4 iterations where 1e-3
/// took 12-15 (the damping then decays by 3 per step over the problem's six decades of
/// eigenvalues), with χ² equal to 1e-8 relative.
pub const TAU: f64 = 1e-9;
/// How far the actual reduction of a screening step may be from the predicted one (ρ = 1 on
/// a quadratic model) for the step to stand for the fit (see [`Lm::screen`]).
pub const SCREEN_RHO: f64 = 0.02;
/// Initial damping of a screening run: the first step is Gauss-Newton's to round-off (the
/// effect columns added to a model at its minimum reach six decades below the largest
/// diagonal, where [`TAU`]'s damping would hold the step back).
pub const SCREEN_TAU: f64 = 1e-15;

use super::progress::{Flow, Observer, Progress};
use super::rows::{in_piece_order, thread_count, weighted_values, Key, Problem};
use super::shared::View;
use super::types::{CalibrationError, State};
use crate::effects::Corrections;
use crate::obs::{PoseError, Residual, RowValue, Step};
use crate::params::{Params, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::HashSet;

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
    /// Stop after the first step when it was taken at the first try and the rows confirmed
    /// its predicted reduction (|ρ − 1| ≤ [`SCREEN_RHO`]): from a neighbouring model's
    /// minimum that step is Gauss-Newton's on a quadratic model that holds, the screening
    /// fit of the diagnosis. Otherwise the run goes on to convergence as without it.
    pub screen: bool,
    /// The start is a neighbouring model's minimum (a warm start): the first step is
    /// Gauss-Newton's ([`SCREEN_TAU`]) instead of [`TAU`]'s, which holds back the directions
    /// six decades below the largest diagonal and takes several steps to release them.
    pub warm: bool,
    /// Per reduced parameter: its index and tolerance (empty: no prior), and the prior's
    /// centre.
    pub prior: Vec<(usize, f64)>,
    pub center: Params,
    /// Per anchored effect parameter: its index among the free ones and its prior's σ
    /// (centred on zero).
    pub theta_prior: Vec<(usize, f64)>,
    /// What each evaluation keeps of its rows for after the fit ([`Keep`]).
    pub keep: Keep,
    /// The normal equations at the start in the unscaled unknowns, without the prior, when
    /// the caller has them from rows it already evaluated there (the plan's, at a cold
    /// start): the LM then starts without evaluating the rows.
    pub initial: Option<Normal>,
    /// The rows at the start read from rows shared with other calibrations (their
    /// `at_warm`), where the start is a warm one they were evaluated at.
    pub shared: Option<&'a View<'a>>,
    /// The effects' corrections already made at some θ (the plan's, at θ₀): an evaluation
    /// there takes them instead of making them again (a warm start at θ₀, every candidate
    /// of a diagnosis: an instrument's alignment of 50 setups makes 15 MB of them).
    pub made: Option<(&'a [f64], &'a Corrections)>,
}

/// What an evaluation of the LM keeps of its rows besides their normal equations, so that
/// the rows at the fit's end need no evaluation of their own: the outlier test reads their
/// values, the posterior their information (and leverages from the pieces' Jacobians). A
/// large campaign keeps nothing: every trial would hold a copy of its row values beside the
/// accepted one's (10⁵ poses: 20 MB each); its final rows are evaluated once after the fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Keep {
    /// Nothing (step 2's virtual rows, a large campaign: their final rows are evaluated
    /// apart).
    Nothing,
    /// The rows' values.
    Values,
    /// The rows' values and each piece's scaled weighted Jacobian (a small campaign's
    /// leverages without evaluating its rows again).
    Jacobians,
}

/// The rows of the point the LM ended at, as its last accepted evaluation saw them.
pub(super) struct Final {
    /// Every row's value, in piece order.
    pub rows: Vec<RowValue>,
    /// JᵀJ of the weighted rows alone (no prior) in the unscaled unknowns.
    pub info: DMatrix<f64>,
    /// Each piece's weighted Jacobian in the unscaled unknowns ([`Keep::Jacobians`]).
    pub jacobians: Option<Vec<DMatrix<f64>>>,
}

/// The normal equations of one point: JᵀJ, Jᵀr and ½‖r‖² of the scaled weighted rows (and
/// the prior's pseudo-rows), summed piece by piece: no m × n Jacobian is ever stored, so a
/// campaign of 10⁵ poses costs the memory of one piece per thread.
#[derive(Clone)]
pub(super) struct Normal {
    pub a: DMatrix<f64>,
    pub g: DVector<f64>,
    pub cost: f64,
}

impl Normal {
    /// The normal equations of weighted rows: their Jacobian `j` (m × n) and values `r`.
    pub fn of(j: &DMatrix<f64>, r: &DVector<f64>) -> Normal {
        Normal {
            a: gram(j),
            g: j.tr_mul(r),
            cost: 0.5 * r.norm_squared(),
        }
    }

    pub fn zeros(cols: usize) -> Normal {
        Normal {
            a: DMatrix::zeros(cols, cols),
            g: DVector::zeros(cols),
            cost: 0.0,
        }
    }

    pub fn add(&mut self, other: &Normal) {
        self.a += &other.a;
        self.g += &other.g;
        self.cost += other.cost;
    }
}

/// Whether `a` and `b` are the same numbers to the bit (corrections made at one are those
/// of the other).
fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// JᵀJ of a block's columns (m × n, stored by column): each entry the dot product of two
/// contiguous columns, the upper triangle only and mirrored (half the products of a general
/// product).
fn gram(j: &DMatrix<f64>) -> DMatrix<f64> {
    let n = j.ncols();
    let mut a = DMatrix::zeros(n, n);
    for c in 0..n {
        for r in 0..=c {
            let v = j.column(r).dot(&j.column(c));
            a[(r, c)] = v;
            a[(c, r)] = v;
        }
    }
    a
}

impl Final {
    /// What `keep` asks of an evaluation's pieces (`parts`, in order) with their summed
    /// normal equations `total` (unscaled, no prior).
    fn gather(total: &Normal, parts: Vec<Piece>, keep: Keep) -> Final {
        Kept::new(total, parts, keep).join()
    }
}

/// What an evaluation kept, still piece by piece: joined into a [`Final`] only at the point
/// the LM ends (a trial followed by another never copies its rows into one vector: 250 kB of
/// fresh pages each on 1,043 poses).
struct Kept {
    info: DMatrix<f64>,
    parts: Vec<Piece>,
    keep: Keep,
}

impl Kept {
    fn new(total: &Normal, parts: Vec<Piece>, keep: Keep) -> Kept {
        Kept {
            info: total.a.clone(),
            parts,
            keep,
        }
    }

    fn join(self) -> Final {
        let mut rows = Vec::with_capacity(self.parts.iter().map(|p| p.rows.len()).sum());
        let mut jacobians = Vec::new();
        for part in self.parts {
            rows.extend(part.rows);
            jacobians.extend(part.jacobian);
        }
        Final {
            rows,
            info: self.info,
            jacobians: (self.keep == Keep::Jacobians).then_some(jacobians),
        }
    }
}

/// One piece's share of an evaluation: its normal equations and what [`Keep`] asks for.
struct Piece {
    normal: Normal,
    rows: Vec<RowValue>,
    jacobian: Option<DMatrix<f64>>,
}

/// The normal equations at a point and what the evaluation kept of its rows.
struct Evaluated {
    normal: Normal,
    kept: Option<Kept>,
}

/// A trial point's rows ([`Lm::trial_at`]): evaluated, or up to their cost (with the
/// prior), JᵀJ deferred until the step is accepted.
enum Trial {
    Done(Evaluated),
    Deferred { cost: f64, parts: Vec<Piece> },
}

impl Trial {
    fn cost(&self) -> f64 {
        match self {
            Trial::Done(evaluated) => evaluated.normal.cost,
            Trial::Deferred { cost, .. } => *cost,
        }
    }
}

/// What a converged run found.
pub(super) struct LmResult {
    pub state: State,
    pub iterations: usize,
    /// Stopped after a screening step (see [`Lm::screen`]), not converged.
    pub screened: bool,
    /// The rows at `state` ([`Keep`]); None when nothing was kept or the LM never
    /// evaluated the rows there (it stopped at a start given as [`Lm::initial`]).
    pub last: Option<Final>,
}

impl Lm<'_> {
    fn n_unknowns(&self) -> usize {
        self.h.len() + self.free_theta.len()
    }

    /// Per reduced parameter: the (parameter, coefficient) terms of its column of D (one
    /// term per identified parameter, more for a parameter others are linked to).
    fn column_terms(&self) -> Vec<Vec<(usize, f64)>> {
        (0..self.h.len())
            .map(|k| {
                (0..N_PARAMS)
                    .filter(|&i| self.d[(i, k)] != 0.0)
                    .map(|i| (i, self.d[(i, k)]))
                    .collect()
            })
            .collect()
    }

    /// The weighted rows' Jacobian in the unknowns, unscaled (m × n): the reduced
    /// parameters' columns from the rows' 29 derivatives through the sparse D (no m × 29
    /// intermediate), then the free effect parameters'.
    fn jacobian(&self, rows: &[Residual], terms: &[Vec<(usize, f64)>]) -> DMatrix<f64> {
        let n = self.h.len();
        // every entry written once, column by column (no zeroed matrix first)
        DMatrix::from_fn(rows.len(), self.n_unknowns(), |i, k| {
            let row = &rows[i];
            if k < n {
                terms[k]
                    .iter()
                    .map(|&(j, d)| row.jacobian[j] / row.sigma * d)
                    .sum()
            } else {
                row.d_theta[self.free_theta[k - n]] / row.sigma
            }
        })
    }

    /// The normal equations of one piece's rows in the unscaled unknowns, and what is kept
    /// of them; with `defer`, JᵀJ left at zero for [`Lm::accepted`] to form from the kept
    /// Jacobian.
    fn piece(
        &self,
        rows: &[Residual],
        terms: &[Vec<(usize, f64)>],
        (keep, defer): (Keep, bool),
    ) -> Piece {
        let jr = self.jacobian(rows, terms);
        let r = weighted_values(rows);
        let normal = if defer {
            let n = self.n_unknowns();
            Normal {
                a: DMatrix::zeros(n, n),
                g: jr.tr_mul(&r),
                cost: 0.5 * r.norm_squared(),
            }
        } else {
            Normal::of(&jr, &r)
        };
        Piece {
            normal,
            rows: if keep == Keep::Nothing {
                Vec::new()
            } else {
                rows.iter().map(RowValue::from).collect()
            },
            jacobian: (keep == Keep::Jacobians).then_some(jr),
        }
    }

    /// The scale of every unknown: the geometric parameters' then the effect parameters'.
    fn scales(&self) -> DVector<f64> {
        DVector::from_iterator(
            self.n_unknowns(),
            self.h.iter().chain(self.h_theta.iter()).copied(),
        )
    }

    /// The rows at `x`, piece by piece in order, and their normal equations summed in the
    /// unscaled unknowns (the posterior's information as it is), without the prior (JᵀJ
    /// zero where `keep.1` defers it).
    fn evaluate(&self, x: &State, keep: (Keep, bool)) -> Result<(Normal, Vec<Piece>), PoseError> {
        let pb = self.problem;
        let made = self
            .made
            .filter(|(theta, corr)| {
                same_bits(theta, &x.theta)
                    && corr.made_at().is_none_or(|at| same_bits(&at.0, &x.p.0))
            })
            .map(|(_, corr)| corr);
        let own;
        let corr = if let Some(corr) = made {
            corr
        } else {
            own = pb.effects.corrections(&x.theta, &x.p);
            &own
        };
        let terms = self.column_terms();
        let parts = pb.map_pieces(self.step, &x.p, &self.p_cal, corr, self.drop, |rows| {
            self.piece(rows, &terms, keep)
        })?;
        let mut total = Normal::zeros(self.n_unknowns());
        for part in &parts {
            total.add(&part.normal);
        }
        Ok((total, parts))
    }

    /// The normal equations at `x` ([`Lm::evaluate`]), scaled, then the prior as pseudo-rows
    /// (p − centre)/tolerance; with what [`Keep`] asks of the rows.
    fn normal_at(&self, x: &State, keep: Keep) -> Result<Evaluated, PoseError> {
        let (total, parts) = self.evaluate(x, (keep, false))?;
        Ok(self.evaluated(x, &total, parts, keep))
    }

    /// The rows at a trial point `x`, evaluated up to what deciding on the step reads: the
    /// cost. Where the pieces keep their Jacobians anyway (a small campaign), JᵀJ waits for
    /// the step to be accepted ([`Lm::accepted`]): a refused trial, the last of most fits,
    /// never forms it. A screening step (`screening`) that keeps nothing keeps its rows'
    /// values: where it stands for the fit they are the final rows, which a large campaign
    /// would otherwise evaluate once more at the same point ([`Lm::final_rows`]: the same
    /// numbers, a third of a screened candidate's passes over the rows).
    fn trial_at(&self, x: &State, screening: bool) -> Result<Trial, PoseError> {
        if self.keep != Keep::Jacobians {
            let keep = if screening && self.keep == Keep::Nothing {
                Keep::Values
            } else {
                self.keep
            };
            return Ok(Trial::Done(self.normal_at(x, keep)?));
        }
        let (total, parts) = self.evaluate(x, (self.keep, true))?;
        // the cost as [`Lm::evaluated`] makes it: scaling leaves it, the prior adds to it
        let mut scaled = self.scaled(&total);
        self.add_prior(&mut scaled, x);
        Ok(Trial::Deferred {
            cost: scaled.cost,
            parts,
        })
    }

    /// The normal equations of an accepted trial at `x`: a deferred JᵀJ formed from the
    /// pieces' kept Jacobians (on the options' threads), then summed in piece order as
    /// [`Lm::normal_at`] sums them: the same numbers.
    fn accepted(&self, x: &State, trial: Trial) -> Evaluated {
        let mut parts = match trial {
            Trial::Done(evaluated) => return evaluated,
            Trial::Deferred { parts, .. } => parts,
        };
        let n = parts.len();
        let threads = thread_count(self.problem.opts.threads).min(n.max(1));
        let grams = in_piece_order(threads, n, |claims| {
            claims
                .map(|k| (k, parts[k].jacobian.as_ref().map(gram)))
                .collect()
        });
        for (part, a) in parts.iter_mut().zip(grams) {
            if let Some(a) = a {
                part.normal.a = a;
            }
        }
        let mut total = Normal::zeros(self.n_unknowns());
        for part in &parts {
            total.add(&part.normal);
        }
        self.evaluated(x, &total, parts, self.keep)
    }

    /// The normal equations at `x` of the shared rows (`view`'s `at_warm`): what
    /// [`Lm::normal_at`] makes of the same rows evaluated.
    fn normal_shared(&self, view: &View, x: &State, keep: Keep) -> Evaluated {
        let terms = self.column_terms();
        let parts = view.map(view.at_warm, |rows| self.piece(rows, &terms, (keep, false)));
        let mut total = Normal::zeros(self.n_unknowns());
        for part in &parts {
            total.add(&part.normal);
        }
        self.evaluated(x, &total, parts, keep)
    }

    /// Unscaled normal equations `total` at `x` and their `parts` as the LM uses them:
    /// scaled, the prior added, what [`Keep`] asks of the rows kept.
    fn evaluated(&self, x: &State, total: &Normal, parts: Vec<Piece>, keep: Keep) -> Evaluated {
        let kept = (keep != Keep::Nothing).then(|| Kept::new(total, parts, keep));
        let mut scaled = self.scaled(total);
        self.add_prior(&mut scaled, x);
        Evaluated {
            normal: scaled,
            kept,
        }
    }

    /// Normal equations in the unscaled unknowns (`u`) in the scaled ones: H A H, H g.
    fn scaled(&self, u: &Normal) -> Normal {
        let s = self.scales();
        Normal {
            a: DMatrix::from_fn(s.len(), s.len(), |i, j| s[i] * u.a[(i, j)] * s[j]),
            g: u.g.component_mul(&s),
            cost: u.cost,
        }
    }

    /// The rows at `x` as the posterior reads them (values and information), where the LM
    /// kept nothing of its last evaluation.
    pub fn final_rows(&self, x: &State) -> Result<Final, PoseError> {
        let (total, parts) = self.evaluate(x, (Keep::Values, false))?;
        Ok(Final::gather(&total, parts, Keep::Values))
    }

    /// The prior's pseudo-rows (p − centre)/tolerance added to normal equations at `x`.
    fn add_prior(&self, total: &mut Normal, x: &State) {
        for (k, &(i, tol)) in self.prior.iter().enumerate() {
            let (r, j) = ((x.p[i] - self.center[i]) / tol, self.h[k] / tol);
            total.a[(k, k)] += j * j;
            total.g[k] += j * r;
            total.cost += 0.5 * r * r;
        }
        let n = self.h.len();
        for &(f, sigma) in &self.theta_prior {
            let (r, j) = (x.theta[self.free_theta[f]] / sigma, self.h_theta[f] / sigma);
            total.a[(n + f, n + f)] += j * j;
            total.g[n + f] += j * r;
            total.cost += 0.5 * r * r;
        }
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

    /// MINPACK's gnorm: the largest |cos| between the residual vector and a Jacobian column
    /// (aᵢᵢ = ‖column i‖², gᵢ = column i · r, ‖r‖² = 2 cost).
    fn gradient_cosine(nq: &Normal) -> f64 {
        let rn = (2.0 * nq.cost).sqrt();
        if rn == 0.0 {
            return 0.0;
        }
        (0..nq.g.len())
            .map(|i| {
                let cn = nq.a[(i, i)].sqrt();
                if cn > 0.0 {
                    (nq.g[i] / (cn * rn)).abs()
                } else {
                    0.0
                }
            })
            .fold(0.0, f64::max)
    }

    /// The normal equations at the start: the caller's ([`Lm::initial`]), from shared rows
    /// ([`Lm::shared`]) or evaluated.
    fn start_at(&self, start: &State) -> Result<Evaluated, PoseError> {
        match (&self.initial, self.shared) {
            (Some(n), _) => {
                let mut normal = self.scaled(n);
                self.add_prior(&mut normal, start);
                Ok(Evaluated { normal, kept: None })
            }
            (None, Some(view)) => Ok(self.normal_shared(view, start, self.keep)),
            (None, None) => self.normal_at(start, self.keep),
        }
    }

    /// The initial damping relative to the largest diagonal: from a neighbour's minimum the
    /// step is Gauss-Newton's, undamped where the normal equations allow.
    fn tau(&self) -> f64 {
        if self.screen || self.warm {
            SCREEN_TAU
        } else {
            TAU
        }
    }

    /// Runs from `start` to convergence; `progress` (the caller's observer, not `Sync`: the
    /// rows are evaluated on other threads) is told of each iteration and may stop the run.
    pub fn run(
        &self,
        start: &State,
        progress: Option<Observer>,
    ) -> Result<LmResult, CalibrationError> {
        let cols = self.n_unknowns();
        let mut p = start.clone();
        let Evaluated {
            normal: mut nq,
            kept: mut last,
        } = self.start_at(&p)?;
        let mut mu = self.tau() * nq.a.diagonal().max();
        let mut nu = 2.0;
        let done = |state: State, iterations: usize, last: Option<Kept>| {
            Ok(LmResult {
                state,
                iterations,
                screened: false,
                last: last.map(Kept::join),
            })
        };
        // distance travelled from the start in the scaled variables (for xtol)
        let mut travelled = DVector::<f64>::zeros(cols);
        for it in 0..self.max_iterations {
            if Self::gradient_cosine(&nq) <= GTOL {
                return done(p, it, last);
            }
            self.observe(progress, it, nq.cost)?;
            let mut damped = nq.a.clone();
            for k in 0..cols {
                damped[(k, k)] += mu;
            }
            let Some(chol) = damped.cholesky() else {
                mu *= nu;
                nu *= 2.0;
                continue;
            };
            let step = -chol.solve(&nq.g);
            let candidate = self.apply(&p, &step);
            let cost = nq.cost;
            let predicted = 0.5 * step.dot(&(step.scale(mu) - &nq.g));
            let trial = self.trial_at(&candidate, self.screen && it == 0).ok();
            match trial {
                Some(trial) if trial.cost() < cost && predicted > 0.0 => {
                    let trial = self.accepted(&candidate, trial);
                    let rho = (cost - trial.normal.cost) / predicted;
                    let actual_rel = (cost - trial.normal.cost) / cost;
                    travelled += &step;
                    p = candidate;
                    nq = trial.normal;
                    last = trial.kept;
                    // Nielsen's rule, with the floor at 1/30 instead of 1/3: ρ ≈ 1 says the
                    // quadratic model holds, so the step goes to Gauss-Newton in two steps
                    // instead of five (measured on 10⁵ self-calibration poses: 11 → 5
                    // iterations, the same χ² to 1e-9)
                    mu *= f64::max(1.0 / 30.0, 1.0 - (2.0 * rho - 1.0).powi(3));
                    nu = 2.0;
                    let ftol = actual_rel <= FTOL && predicted / cost <= FTOL && rho <= 2.0;
                    let xtol = step.norm() <= XTOL * (travelled.norm() + XTOL);
                    if ftol || xtol || nq.cost == 0.0 {
                        return done(p, it + 1, last);
                    }
                    if self.screen && it == 0 && (rho - 1.0).abs() <= SCREEN_RHO {
                        return Ok(LmResult {
                            state: p,
                            iterations: 1,
                            screened: true,
                            last: last.map(Kept::join),
                        });
                    }
                }
                _ => {
                    // MINPACK applies ftol to a refused step too: a cost that no longer moves
                    // beyond round-off, and a model that predicts no more, is the minimum
                    if let Some(trial) = trial {
                        let actual = (cost - trial.cost()) / cost;
                        if actual.abs() <= FTOL && predicted / cost <= FTOL {
                            return done(p, it + 1, last);
                        }
                    }
                    // a step that raises the cost or leaves the assembly mode is refused
                    mu *= nu;
                    nu *= 2.0;
                    if mu > 1e30 {
                        // no step lowers the cost: a minimum to machine precision, unless
                        // the gradient says otherwise
                        if nq.g.amax() < 1e-3 * (1.0 + cost) {
                            return done(p, it + 1, last);
                        }
                        return Err(Self::not_converged(it + 1, &nq));
                    }
                }
            }
        }
        Err(Self::not_converged(self.max_iterations, &nq))
    }

    /// Tells the observer that iteration `it` (from 0) begins at `cost`: once per iteration
    /// the run counts (a refused step and a failed factorisation count too).
    fn observe(
        &self,
        progress: Option<Observer>,
        it: usize,
        cost: f64,
    ) -> Result<(), CalibrationError> {
        if self
            .problem
            .opts
            .stop
            .as_ref()
            .is_some_and(super::types::Stop::requested)
        {
            return Err(CalibrationError::Cancelled);
        }
        let Some(observer) = progress else {
            return Ok(());
        };
        let at = Progress::Iteration {
            step: self.step,
            iteration: it + 1,
            cost,
        };
        match observer(&at) {
            Flow::Continue => Ok(()),
            Flow::Stop => Err(CalibrationError::Cancelled),
        }
    }

    fn not_converged(iterations: usize, nq: &Normal) -> CalibrationError {
        CalibrationError::NotConverged {
            iterations,
            cost: nq.cost,
            gradient: nq.g.amax(),
        }
    }
}
