//! Geometric calibration (thesis chapter 3, 4.2-4.3): Levenberg-Marquardt on the weighted
//! model-minus-measurement rows of `obs`, with parameter scaling, the dependency matrix D,
//! outlier elimination per measurement direction, parameter uncertainties, and the two-step
//! procedure of the forward instruments.

use crate::campaign::{Campaign, Instrument};
use crate::effects::{Corrections, EffectSet};
use crate::noise::NoiseModel;
use crate::obs::{self, Direction, PoseError, Residual, Step};
use crate::observability::{condition_number, normalize_columns, qr_pivot_order};
use crate::params::{self, unit, variation_range, Model, Params, Unit, NAMES, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::{BTreeMap, HashSet};

/// Which parameters the calibration identifies.
#[derive(Clone, Debug, PartialEq)]
pub enum Selection {
    /// From the observability analysis of the campaign: parameters in QR-pivot order while
    /// the condition number stays below `max_condition` (100 after Schröer).
    Auto { max_condition: f64 },
    /// An explicit list of parameter indexes.
    List(Vec<usize>),
    /// Every parameter of the model, each pulled towards its nominal value by its
    /// manufacturing tolerance (maximum a posteriori): the campaign determines the parameter
    /// combinations it sees better than the tolerance, the others stay at the prior. No
    /// condition-number cut to choose, so every command calibrates the same way.
    Prior(Prior),
}

/// Manufacturing tolerances of the geometric parameters (one standard deviation): the prior
/// of a [`Selection::Prior`] calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    pub length_mm: f64,
    pub angle_rad: f64,
}

impl Default for Prior {
    /// 0.1 mm and 1 mrad: a machined and assembled frame of this size.
    fn default() -> Self {
        Prior {
            length_mm: 0.1,
            angle_rad: 1e-3,
        }
    }
}

impl Prior {
    /// The tolerance of parameter `i` (mm or rad).
    pub fn sigma(&self, i: usize) -> f64 {
        match unit(i) {
            Unit::Mm => self.length_mm,
            Unit::Rad => self.angle_rad,
        }
    }
}

/// Parameter scaling (eq. 3.23-3.25).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Scaling {
    /// h_k = 1 / ‖J_k‖: column norms of the weighted Jacobian.
    #[default]
    ColumnNorm,
    /// h_k = the parameter's plausible variation (0.1 mm, 1°), after Schröer.
    Range,
}

/// A linked parameter (a row of the dependency matrix D, eq. 3.35): Δp_param = Σ a·Δp_j.
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    pub param: usize,
    pub terms: Vec<(usize, f64)>,
}

impl Link {
    /// The perfect parallel-holder as links: rod 5 follows rod 4 (l5 = l4, xa5r = xa4r, ...).
    pub fn perfect_parallelogram() -> Vec<Link> {
        use params::*;
        [
            (L5, L4),
            (XA5R, XA4R),
            (YA5R, YA4R),
            (XB5R, XB4R),
            (YB5R, YB4R),
        ]
        .into_iter()
        .map(|(p, j)| Link {
            param: p,
            terms: vec![(j, 1.0)],
        })
        .collect()
    }
}

/// Options of a calibration.
#[derive(Clone, Debug)]
pub struct Options {
    pub model: Model,
    pub selection: Selection,
    pub links: Vec<Link>,
    pub scaling: Scaling,
    /// Rows further than this many standard deviations from their direction's mean are
    /// eliminated (eq. 3.31-3.32); None keeps every row.
    pub outlier_sigma: Option<f64>,
    pub max_iterations: usize,
    /// The instruments' and encoders' noise: the rows' weights.
    pub noise: NoiseModel,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            model: Model::M29,
            selection: Selection::Prior(Prior::default()),
            links: Vec::new(),
            scaling: Scaling::ColumnNorm,
            outlier_sigma: Some(3.0),
            max_iterations: 100,
            noise: NoiseModel::default(),
        }
    }
}

/// Why a calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    #[error(transparent)]
    Pose(#[from] PoseError),
    #[error("{0}: the campaign has no calibration measurements (only circle/none rows or resets)")]
    NoMeasurements(String),
    #[error("parameter {0} does not belong to {1}")]
    NotInModel(&'static str, Model),
    #[error("parameter {0} has no influence on these measurements (zero Jacobian column)")]
    Unobservable(&'static str),
    #[error("no parameter is observable with this campaign")]
    NothingToIdentify,
    #[error("more parameters ({params}) than measurement rows ({rows})")]
    Underdetermined { params: usize, rows: usize },
    #[error("Levenberg-Marquardt did not converge in {iterations} iterations (cost {cost:.4e}, gradient {gradient:.3e})")]
    NotConverged {
        iterations: usize,
        cost: f64,
        gradient: f64,
    },
    #[error(
        "the normal equations are singular: identified parameters are linearly dependent ({0})"
    )]
    Singular(String),
}

/// A row removed as an outlier.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Outlier {
    /// Source line of the pose.
    pub line: usize,
    pub instrument: String,
    pub direction: String,
    /// Residual at removal, mm (rad for ψ).
    pub residual: f64,
    /// Its distance from the direction's mean in standard deviations.
    pub deviations: f64,
}

/// RMS of one instrument and direction.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DirectionRms {
    pub instrument: String,
    pub direction: String,
    pub rows: usize,
    /// mm, or rad for ψ.
    pub rms_before: f64,
    pub rms_after: f64,
    pub is_angle: bool,
}

/// One identified parameter.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Identified {
    pub name: &'static str,
    pub index: usize,
    pub nominal: f64,
    pub value: f64,
    pub sigma: f64,
    /// Which step identified it: 1 (direct rows) or 2 (virtual q2 rows of forward instruments).
    pub step: u8,
}

/// One parameter of an effect in the model.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EffectEstimate {
    pub effect: &'static str,
    pub name: String,
    pub unit: &'static str,
    pub value: f64,
    pub sigma: f64,
    /// Fraction (0..1) of the parameter's signature in the measurements that the geometric
    /// parameters (and the effect parameters before it) cannot mimic: near 0, the campaign
    /// cannot tell it from a geometric error and it is held at its start value.
    pub observability: f64,
    /// Whether it was identified (false: held, unobservable with this campaign).
    pub identified: bool,
    /// The plausible magnitude the effect declares for it (its unit).
    pub prior: f64,
}

/// The result of a calibration.
#[derive(Clone, Debug)]
pub struct Calibration {
    pub model: Model,
    pub start: Params,
    pub params: Params,
    pub identified: Vec<Identified>,
    pub iterations: usize,
    /// Condition number of the column-normalised weighted Jacobian of the identified
    /// parameters (step 1).
    pub condition_number: f64,
    pub outliers: Vec<Outlier>,
    pub rms: Vec<DirectionRms>,
    /// Weighted cost ½ Σ (r/σ)² before and after; the chi-square per degree of freedom after.
    pub cost_before: f64,
    pub cost_after: f64,
    pub chi2_per_dof: f64,
    pub rows: usize,
    /// Effect parameters θ (all of them, in [`EffectSet::layout`] order) and their estimates.
    pub theta: Vec<f64>,
    pub effects: Vec<EffectEstimate>,
    /// Degrees of freedom used: identified geometric and effect parameters.
    pub n_identified: usize,
    /// Effective number of parameters the data determine (the trace of the hat matrix):
    /// `n_identified` without a prior, less where the prior holds a combination.
    pub dof_model: f64,
    /// With a prior: how many parameter combinations the campaign determined better than
    /// their tolerance, out of how many.
    pub determined: Option<(usize, usize)>,
    /// The final rows of step 1 (the measurements) and their leverages (diagonal of the
    /// hat matrix), for the noise estimation.
    pub residuals: Vec<Residual>,
    pub leverage: Vec<f64>,
}

/// The dependency matrix D (29 × n) for the identified `ids` with `links`.
fn dependency(ids: &[usize], links: &[Link]) -> DMatrix<f64> {
    let mut d = DMatrix::zeros(N_PARAMS, ids.len());
    for (k, &i) in ids.iter().enumerate() {
        d[(i, k)] = 1.0;
    }
    for link in links {
        for &(j, a) in &link.terms {
            if let Some(k) = ids.iter().position(|&i| i == j) {
                d[(link.param, k)] += a;
            }
        }
    }
    d
}

/// Weighted residual vector and weighted Jacobian (m × 29) of rows.
fn weighted(rows: &[Residual]) -> (DVector<f64>, DMatrix<f64>) {
    let r = DVector::from_iterator(rows.len(), rows.iter().map(|row| row.value / row.sigma));
    let j = DMatrix::from_fn(rows.len(), N_PARAMS, |i, k| {
        rows[i].jacobian[k] / rows[i].sigma
    });
    (r, j)
}

/// Weighted Jacobian columns (m × k) of the effect parameters `free`.
fn weighted_theta(rows: &[Residual], free: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), free.len(), |i, k| {
        rows[i].d_theta.get(free[k]).copied().unwrap_or(0.0) / rows[i].sigma
    })
}

type Key = (usize, Direction);

#[allow(clippy::too_many_arguments)]
fn rows_at(
    c: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
    corr: &Corrections,
    drop: &HashSet<Key>,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PoseError> {
    let mut rows = obs::residuals_with(c, p, model, step, p_cal, corr, noise)?;
    rows.retain(|r| !drop.contains(&(r.pose, r.direction)));
    Ok(rows)
}

/// Levenberg-Marquardt with Nielsen's damping update (Madsen, Nielsen, Tingleff 2004), on the
/// scaled variables δ = H⁻¹ Δp_red (eq. 3.24).
struct Lm<'a> {
    campaign: &'a Campaign,
    model: Model,
    step: Step,
    p_cal: Params,
    drop: &'a HashSet<Key>,
    d: DMatrix<f64>,
    h: DVector<f64>,
    /// Effects, the identified effect parameters and their scaling.
    effects: &'a EffectSet,
    free_theta: &'a [usize],
    h_theta: DVector<f64>,
    max_iterations: usize,
    noise: &'a NoiseModel,
    /// Per reduced parameter: its index and tolerance (empty: no prior), and the prior's
    /// centre.
    prior: Vec<(usize, f64)>,
    center: Params,
}

/// The unknowns of a calibration: geometric parameters and effect parameters.
#[derive(Clone, Debug)]
struct State {
    p: Params,
    theta: Vec<f64>,
}

struct LmResult {
    state: State,
    iterations: usize,
}

impl Lm<'_> {
    fn eval(&self, x: &State) -> Result<(DVector<f64>, DMatrix<f64>), PoseError> {
        let corr = self.effects.corrections(&x.theta);
        let rows = rows_at(
            self.campaign,
            &x.p,
            self.model,
            self.step,
            &self.p_cal,
            &corr,
            self.drop,
            self.noise,
        )?;
        let (r, j) = weighted(&rows);
        let jg = j * &self.d * DMatrix::from_diagonal(&self.h);
        let jt = weighted_theta(&rows, self.free_theta) * DMatrix::from_diagonal(&self.h_theta);
        let (m, n) = (jg.nrows(), jg.ncols());
        let np = self.prior.len();
        // the prior as pseudo-rows (p − centre)/tolerance below the measurements
        let mut js = DMatrix::zeros(m + np, n + jt.ncols());
        js.view_mut((0, 0), (m, n)).copy_from(&jg);
        js.view_mut((0, n), (m, jt.ncols())).copy_from(&jt);
        let mut rs = DVector::zeros(m + np);
        rs.rows_mut(0, m).copy_from(&r);
        for (k, &(i, tol)) in self.prior.iter().enumerate() {
            rs[m + k] = (x.p[i] - self.center[i]) / tol;
            js[(m + k, k)] = self.h[k] / tol;
        }
        Ok((rs, js))
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

    fn run(&self, start: &State) -> Result<LmResult, CalibrationError> {
        let mut p = start.clone();
        let (mut r, mut js) = self.eval(&p)?;
        let mut cost = 0.5 * r.norm_squared();
        let mut a = js.transpose() * &js;
        let mut g = js.transpose() * &r;
        let mut mu = 1e-3 * a.diagonal().max();
        let mut nu = 2.0;
        for it in 0..self.max_iterations {
            if g.amax() < 1e-9 * (1.0 + cost) {
                return Ok(LmResult {
                    state: p,
                    iterations: it,
                });
            }
            let mut damped = a.clone();
            for k in 0..damped.nrows() {
                damped[(k, k)] += mu;
            }
            let Some(chol) = damped.cholesky() else {
                mu *= nu;
                nu *= 2.0;
                continue;
            };
            let step = -chol.solve(&g);
            let candidate = self.apply(&p, &step);
            let predicted = 0.5 * step.dot(&(step.scale(mu) - &g));
            let trial = self
                .eval(&candidate)
                .ok()
                .map(|(r2, j2)| (0.5 * r2.norm_squared(), r2, j2));
            match trial {
                Some((cost2, r2, j2)) if cost2 < cost && predicted > 0.0 => {
                    let rho = (cost - cost2) / predicted;
                    let small = cost - cost2 <= 1e-12 * cost;
                    p = candidate;
                    r = r2;
                    js = j2;
                    cost = cost2;
                    a = js.transpose() * &js;
                    g = js.transpose() * &r;
                    mu *= f64::max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0).powi(3));
                    nu = 2.0;
                    if small || step.norm() < 1e-12 {
                        return Ok(LmResult {
                            state: p,
                            iterations: it + 1,
                        });
                    }
                }
                _ => {
                    // a step that raises the cost or leaves the assembly mode is refused
                    mu *= nu;
                    nu *= 2.0;
                    if mu > 1e30 {
                        // no step lowers the cost: a minimum to machine precision, unless
                        // the gradient says otherwise
                        if g.amax() < 1e-3 * (1.0 + cost) {
                            return Ok(LmResult {
                                state: p,
                                iterations: it + 1,
                            });
                        }
                        return Err(CalibrationError::NotConverged {
                            iterations: it + 1,
                            cost,
                            gradient: g.amax(),
                        });
                    }
                }
            }
        }
        Err(CalibrationError::NotConverged {
            iterations: self.max_iterations,
            cost,
            gradient: g.amax(),
        })
    }
}

/// Weighted Jacobian columns (m × n) for parameters `ids` under links, at `p`.
fn reduced_jacobian(rows: &[Residual], ids: &[usize], links: &[Link]) -> DMatrix<f64> {
    let (_, j) = weighted(rows);
    j * dependency(ids, links)
}

/// Parameters of `candidates` in observability order, kept while the condition number of
/// the column-normalised Jacobian stays below `max_condition`.
pub fn auto_select(
    rows: &[Residual],
    candidates: &[usize],
    links: &[Link],
    max_condition: f64,
) -> Vec<usize> {
    let jr = reduced_jacobian(rows, candidates, links);
    let range = DVector::from_iterator(
        candidates.len(),
        candidates.iter().map(|&i| variation_range(i)),
    );
    let scaled = jr * DMatrix::from_diagonal(&range);
    let mut chosen = Vec::new();
    for ranked in qr_pivot_order(&scaled) {
        if !(ranked.condition_number < max_condition) {
            break;
        }
        chosen.push(candidates[ranked.column]);
    }
    chosen
}

fn scaling_vector(
    jr: &DMatrix<f64>,
    ids: &[usize],
    scaling: Scaling,
) -> Result<DVector<f64>, CalibrationError> {
    let mut h = DVector::zeros(ids.len());
    for (k, &i) in ids.iter().enumerate() {
        let n = jr.column(k).norm();
        if !(n > 0.0) {
            return Err(CalibrationError::Unobservable(NAMES[i]));
        }
        h[k] = match scaling {
            Scaling::ColumnNorm => 1.0 / n,
            Scaling::Range => variation_range(i),
        };
    }
    Ok(h)
}

/// Rows further than `k` standard deviations from the mean of their instrument and direction.
fn find_outliers(rows: &[Residual], campaign: &Campaign, k: f64) -> Vec<(Key, Outlier)> {
    let mut groups: BTreeMap<(&str, Direction), Vec<&Residual>> = BTreeMap::new();
    for r in rows {
        groups
            .entry((r.instrument.as_str(), r.direction))
            .or_default()
            .push(r);
    }
    let mut out = Vec::new();
    for ((inst, dir), g) in groups {
        if g.len() < 8 {
            continue; // too few rows for a trustworthy standard deviation
        }
        let n = g.len() as f64;
        let mean = g.iter().map(|r| r.value).sum::<f64>() / n;
        let sd = (g.iter().map(|r| (r.value - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        for r in g {
            let dev = (r.value - mean).abs() / sd;
            if sd > 0.0 && dev > k {
                out.push((
                    (r.pose, r.direction),
                    Outlier {
                        line: campaign.poses[r.pose].line,
                        instrument: inst.to_string(),
                        direction: dir.to_string(),
                        residual: r.value,
                        deviations: dev,
                    },
                ));
            }
        }
    }
    out
}

/// Rod-2 parameters: identified by the virtual q2 step of forward instruments.
fn rod2_params() -> [usize; 5] {
    use params::*;
    [L2, XA2R, YA2R, XB2R, YB2R]
}

/// RMS per instrument and direction of two row sets (same rows, two parameter sets).
fn rms_table(before: &[Residual], after: &[Residual]) -> Vec<DirectionRms> {
    let mut acc: BTreeMap<(Instrument, Direction), (usize, f64, f64)> = BTreeMap::new();
    let key = |r: &Residual| (r.instrument, r.direction);
    for r in before {
        let e = acc.entry(key(r)).or_default();
        e.0 += 1;
        e.1 += r.value * r.value;
    }
    for r in after {
        acc.entry(key(r)).or_default().2 += r.value * r.value;
    }
    acc.into_iter()
        .map(|((inst, dir), (n, b, a))| DirectionRms {
            instrument: inst.as_str().to_string(),
            direction: dir.to_string(),
            rows: n,
            rms_before: (b / n.max(1) as f64).sqrt(),
            rms_after: (a / n.max(1) as f64).sqrt(),
            is_angle: dir.is_angle(),
        })
        .collect()
}

/// What the final fit of step 1 tells about its unknowns (scaled by nothing: the caller
/// multiplies by the variance factor).
struct Posterior {
    /// Covariance (JᵀJ + Λ)⁻¹ of the identified geometric parameters (Λ: the prior's
    /// precision, zero without one).
    cov1: DMatrix<f64>,
    /// Standard deviations of the free effect parameters.
    sig_theta: Vec<f64>,
    /// tr((JᵀJ + Λ)⁻¹ JᵀJ): the parameters the data determine.
    dof_model: f64,
    /// Diagonal of the hat matrix J (JᵀJ + Λ)⁻¹ Jᵀ, one per row.
    leverage: Vec<f64>,
    determined: Option<(usize, usize)>,
}

fn posterior(
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
fn step2_uncertainties(
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

/// Calibrate `campaign` starting from `start`.
pub fn calibrate(
    campaign: &Campaign,
    start: &Params,
    opts: &Options,
) -> Result<Calibration, CalibrationError> {
    calibrate_with(campaign, start, opts, &EffectSet::empty(), &[])
}

/// Fraction of an effect parameter's signature that the geometric columns (and the effect
/// columns before it) cannot mimic, below which it is held: numerically absorbed.
pub const MIN_EFFECT_OBSERVABILITY: f64 = 1e-6;
/// Size of that unmimicked signature for a parameter at its prior magnitude, in units of the
/// measurements' σ (root of its χ² contribution), below which it is held: a prior-sized value
/// would not move the fit by one standard deviation.
pub const MIN_EFFECT_SIGNAL: f64 = 1.0;

/// Calibrate `campaign` with the physical `effects` (bound to it) in the model, starting from
/// `start` and effect parameters `theta0` (empty: all zero). The geometric parameters are
/// selected as without effects; every effect parameter the campaign can tell from the
/// geometry (see [`EffectEstimate::observability`]) is identified with them.
pub fn calibrate_with(
    campaign: &Campaign,
    start: &Params,
    opts: &Options,
    effects: &EffectSet,
    theta0: &[f64],
) -> Result<Calibration, CalibrationError> {
    let model = opts.model;
    if let Selection::List(list) = &opts.selection {
        if let Some(&i) = list.iter().find(|&&i| !model.has_param(i)) {
            return Err(CalibrationError::NotInModel(NAMES[i], model));
        }
    }
    let n_theta = effects.n_params();
    let theta0: Vec<f64> = if theta0.len() == n_theta {
        theta0.to_vec()
    } else {
        vec![0.0; n_theta]
    };
    let corr0 = effects.corrections(&theta0);
    let linked: HashSet<usize> = opts.links.iter().map(|l| l.param).collect();
    let no_drop = HashSet::new();
    let noise = &opts.noise;
    // the direct rows (step 1) at parameters p with corrections corr, less the rows dropped
    let direct = |p: &Params, corr: &Corrections, drop: &HashSet<Key>| {
        rows_at(campaign, p, model, Step::Direct, start, corr, drop, noise)
    };
    let rows0 = direct(start, &corr0, &no_drop)?;
    if rows0.is_empty() {
        return Err(CalibrationError::NoMeasurements(campaign.source.clone()));
    }
    let (step1_ids, step2_wanted) = select_geometric(campaign, &rows0, opts, &linked)?;
    let prior1 = prior_of(&opts.selection, &step1_ids);
    if prior1.is_empty() && rows0.len() < step1_ids.len() {
        return Err(CalibrationError::Underdetermined {
            params: step1_ids.len(),
            rows: rows0.len(),
        });
    }
    let layout = effects.layout();
    let observability = effect_observability(&rows0, &step1_ids, &opts.links, effects);
    let free_theta: Vec<usize> = (0..n_theta)
        .filter(|&k| !effects.is_held(k))
        .filter(|&k| {
            let (frac, signal) = observability[k];
            frac >= MIN_EFFECT_OBSERVABILITY && signal * layout[k].1.prior >= MIN_EFFECT_SIGNAL
        })
        .collect();
    let observability: Vec<f64> = observability.iter().map(|o| o.0).collect();
    let h_theta = DVector::from_iterator(
        free_theta.len(),
        free_theta.iter().map(|&k| layout[k].1.prior),
    );

    // Step 1 with outlier elimination rounds.
    let jr0 = reduced_jacobian(&rows0, &step1_ids, &opts.links);
    let h = scaling_vector(&jr0, &step1_ids, opts.scaling)?;
    let condition = condition_number(&normalize_columns(&jr0));
    let mut drop: HashSet<Key> = HashSet::new();
    let mut outliers = Vec::new();
    let mut x = State {
        p: *start,
        theta: theta0.clone(),
    };
    let mut iterations = 0;
    loop {
        let lm = Lm {
            campaign,
            model,
            step: Step::Direct,
            p_cal: *start,
            drop: &drop,
            d: dependency(&step1_ids, &opts.links),
            h: h.clone(),
            effects,
            free_theta: &free_theta,
            h_theta: h_theta.clone(),
            max_iterations: opts.max_iterations,
            noise,
            prior: prior1.clone(),
            center: *start,
        };
        let res = lm.run(&x)?;
        x = res.state;
        iterations += res.iterations;
        let Some(k) = opts.outlier_sigma else { break };
        let corr = effects.corrections(&x.theta);
        let rows = direct(&x.p, &corr, &drop)?;
        let found = find_outliers(&rows, campaign, k);
        if found.is_empty() || outliers.len() > rows0.len() / 20 {
            break;
        }
        for (key, o) in found {
            drop.insert(key);
            outliers.push(o);
        }
    }
    let corr = effects.corrections(&x.theta);
    let rows_final = direct(&x.p, &corr, &drop)?;
    let n_identified = step1_ids.len() + free_theta.len();
    let post = posterior(&rows_final, &step1_ids, &opts.links, &free_theta, &prior1)?;
    // chi-square of the measurements themselves (not the prior, nor the virtual rows of step 2)
    let chi2 = 2.0 * cost_of(&rows_final);
    let chi2_per_dof = chi2 / (rows_final.len() as f64 - post.dof_model).max(1.0);
    let s2 = chi2_per_dof.max(1.0);
    let cov1 = &post.cov1 * s2;
    let cov_theta: Vec<f64> = post.sig_theta.iter().map(|s| s * s2.sqrt()).collect();
    let sig1: Vec<f64> = (0..step1_ids.len())
        .map(|k| cov1[(k, k)].max(0.0).sqrt())
        .collect();
    let d1 = dependency(&step1_ids, &opts.links);
    let cov_p1 = &d1 * &cov1 * d1.transpose();
    let mut identified: Vec<Identified> = step1_ids
        .iter()
        .zip(&sig1)
        .map(|(&i, &s)| Identified {
            name: NAMES[i],
            index: i,
            nominal: start[i],
            value: x.p[i],
            sigma: s,
            step: 1,
        })
        .collect();
    let effect_estimates = layout
        .iter()
        .enumerate()
        .map(|(k, (effect, prm, _, _))| {
            let free = free_theta.iter().position(|&f| f == k);
            EffectEstimate {
                effect,
                name: prm.name.clone(),
                unit: prm.unit,
                value: x.theta[k],
                sigma: free.map_or(0.0, |f| cov_theta[f]),
                observability: observability[k],
                identified: free.is_some(),
                prior: prm.prior,
            }
        })
        .collect();
    let mut before_rows: Vec<Residual> = direct(start, &corr0, &drop)?;
    let mut after_rows = rows_final.clone();

    // Step 2: rod 2 from virtual measurements of the forward instruments (eq. 4.32).
    let mut p = x.p;
    if !step2_wanted.is_empty() {
        let p1 = p;
        // the virtual q2 rows at p, their virtual measurements made with step 1's p1
        let virtual_rows = |p: &Params| {
            rows_at(
                campaign,
                p,
                model,
                Step::VirtualQ2,
                &p1,
                &corr,
                &drop,
                noise,
            )
        };
        let rows2 = virtual_rows(&p1)?;
        let ids2 = match &opts.selection {
            Selection::Auto { max_condition } => {
                auto_select(&rows2, &step2_wanted, &[], *max_condition)
            }
            Selection::List(_) | Selection::Prior(_) => step2_wanted.clone(),
        };
        let prior2 = prior_of(&opts.selection, &ids2);
        if !ids2.is_empty() {
            let jr2 = reduced_jacobian(&rows2, &ids2, &[]);
            let h2 = scaling_vector(&jr2, &ids2, opts.scaling)?;
            let lm = Lm {
                campaign,
                model,
                step: Step::VirtualQ2,
                p_cal: p1,
                drop: &drop,
                d: dependency(&ids2, &[]),
                h: h2,
                // the effects stay in the rows at their identified values
                effects,
                free_theta: &[],
                h_theta: DVector::zeros(0),
                max_iterations: opts.max_iterations,
                noise,
                prior: prior2.clone(),
                center: *start,
            };
            let res = lm.run(&State {
                p: p1,
                theta: x.theta.clone(),
            })?;
            p = res.state.p;
            iterations += res.iterations;
            let rows2_after = virtual_rows(&p)?;
            let sig2 = step2_uncertainties(&rows2_after, &ids2, &prior2, &cov_p1)?;
            identified.extend(ids2.iter().zip(&sig2).map(|(&i, &s)| Identified {
                name: NAMES[i],
                index: i,
                nominal: start[i],
                value: p[i],
                sigma: s,
                step: 2,
            }));
            before_rows.extend(rows_at(
                campaign,
                start,
                model,
                Step::VirtualQ2,
                start,
                &corr0,
                &drop,
                noise,
            )?);
            after_rows.extend(rows2_after);
        }
    }
    Ok(Calibration {
        model,
        start: *start,
        params: p,
        identified,
        iterations,
        condition_number: condition,
        outliers,
        rms: rms_table(&before_rows, &after_rows),
        cost_before: cost_of(&before_rows),
        cost_after: cost_of(&after_rows),
        chi2_per_dof,
        rows: after_rows.len(),
        theta: x.theta,
        effects: effect_estimates,
        n_identified,
        dof_model: post.dof_model,
        determined: post.determined,
        residuals: rows_final,
        leverage: post.leverage,
    })
}

/// ½ Σ (r/σ)² of rows.
fn cost_of(rows: &[Residual]) -> f64 {
    0.5 * rows
        .iter()
        .map(|r| (r.value / r.sigma).powi(2))
        .sum::<f64>()
}

/// The prior's (parameter, tolerance) of each of `ids`; empty without a prior.
fn prior_of(selection: &Selection, ids: &[usize]) -> Vec<(usize, f64)> {
    match selection {
        Selection::Prior(prior) => ids.iter().map(|&i| (i, prior.sigma(i))).collect(),
        _ => Vec::new(),
    }
}

/// Step 1's identified geometric parameters, and the rod-2 parameters wanted from step 2.
fn select_geometric(
    campaign: &Campaign,
    rows0: &[Residual],
    opts: &Options,
    linked: &HashSet<usize>,
) -> Result<(Vec<usize>, Vec<usize>), CalibrationError> {
    let model = opts.model;
    // Candidates of step 1: the model's free parameters with an influence on the direct rows.
    let (_, j0) = weighted(rows0);
    // (relative threshold: the subsystem solves carry round-off derivatives of ~1e-17)
    let col_max = (0..N_PARAMS)
        .map(|i| j0.column(i).norm() * variation_range(i))
        .fold(0.0, f64::max);
    let visible = |i: usize| j0.column(i).norm() * variation_range(i) > 1e-9 * col_max;
    let influences = |i: usize| {
        visible(i)
            || opts
                .links
                .iter()
                .any(|l| l.terms.iter().any(|t| t.0 == i) && visible(l.param))
    };
    let free: Vec<usize> = model
        .params()
        .into_iter()
        .filter(|i| !linked.contains(i))
        .collect();
    let step1_ids: Vec<usize> = match &opts.selection {
        Selection::Auto { max_condition } => {
            let cands: Vec<usize> = free.iter().copied().filter(|&i| influences(i)).collect();
            auto_select(rows0, &cands, &opts.links, *max_condition)
        }
        Selection::List(list) => list.iter().copied().filter(|&i| influences(i)).collect(),
        Selection::Prior(_) => free.iter().copied().filter(|&i| influences(i)).collect(),
    };
    let step2_wanted: Vec<usize> = if obs::has_forward_instruments(campaign) {
        let r2 = rod2_params();
        match &opts.selection {
            Selection::Auto { .. } | Selection::Prior(_) => r2
                .iter()
                .copied()
                .filter(|i| !step1_ids.contains(i))
                .collect(),
            Selection::List(list) => list
                .iter()
                .copied()
                .filter(|i| r2.contains(i) && !step1_ids.contains(i))
                .collect(),
        }
    } else {
        Vec::new()
    };
    if let Selection::List(list) = &opts.selection {
        if let Some(&i) = list
            .iter()
            .find(|i| !step1_ids.contains(i) && !step2_wanted.contains(i))
        {
            return Err(CalibrationError::Unobservable(NAMES[i]));
        }
    }
    if step1_ids.is_empty() {
        return Err(CalibrationError::NothingToIdentify);
    }
    Ok((step1_ids, step2_wanted))
}

/// For each effect parameter, the fraction of its weighted column that lies outside the span
/// of the identified geometric columns and of the effect columns before it (Gram-Schmidt in
/// layout order: 1 = fully distinct, 0 = a geometric error in disguise), and the norm of that
/// outside part (σ units per unit of the parameter).
fn effect_observability(
    rows: &[Residual],
    ids: &[usize],
    links: &[Link],
    effects: &EffectSet,
) -> Vec<(f64, f64)> {
    let n = effects.n_params();
    if n == 0 {
        return Vec::new();
    }
    let jg = normalize_columns(&reduced_jacobian(rows, ids, links));
    let all: Vec<usize> = (0..n).collect();
    let jt = weighted_theta(rows, &all);
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let add = |v: DVector<f64>, basis: &mut Vec<DVector<f64>>| -> (f64, f64) {
        let norm0 = v.norm();
        if !(norm0 > 0.0) {
            return (0.0, 0.0);
        }
        let mut w = v;
        // twice: classical Gram-Schmidt loses orthogonality on near-dependent columns
        for _ in 0..2 {
            for b in basis.iter() {
                let c = b.dot(&w);
                w -= b * c;
            }
        }
        let rest = w.norm();
        if rest / norm0 > 1e-12 {
            basis.push(w.unscale(rest));
        }
        (rest / norm0, rest)
    };
    for k in 0..jg.ncols() {
        add(jg.column(k).into_owned(), &mut basis);
    }
    (0..n)
        .map(|k| add(jt.column(k).into_owned(), &mut basis))
        .collect()
}

/// Calibration gain on held-out measurement errors (eq. 3.33-3.34): the mean over values of
/// (|ΔW_nc| − |ΔW_cal|) / |ΔW_nc|.
pub fn gain(before: &[f64], after: &[f64]) -> f64 {
    let terms: Vec<f64> = before
        .iter()
        .zip(after)
        .filter(|(b, _)| b.abs() > 0.0)
        .map(|(b, a)| (b.abs() - a.abs()) / b.abs())
        .collect();
    if terms.is_empty() {
        0.0
    } else {
        terms.iter().sum::<f64>() / terms.len() as f64
    }
}

/// RMS of a set of values.
pub fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}
