//! Geometric calibration (thesis chapter 3, 4.2-4.3): Levenberg-Marquardt on the weighted
//! model-minus-measurement rows of `obs`, with parameter scaling, the dependency matrix D,
//! outlier elimination per measurement direction, parameter uncertainties, and the two-step
//! procedure of the forward instruments.

mod lm;
pub mod online;
mod progress;
mod report;
mod request;
mod rows;
mod select;
mod shared;
mod uncertainty;

pub use progress::{Flow, Observer, Progress};
pub use report::{gain, rms};
pub use request::{calibrate, Noise, Request};
pub use select::{MIN_EFFECT_OBSERVABILITY, MIN_EFFECT_SIGNAL};
pub use shared::SharedRows;

use crate::campaign::Campaign;
use crate::effects::{Corrections, EffectSet};
use crate::noise::NoiseModel;
use crate::obs::{PoseError, Residual, RowValue, Step};
use crate::observability::{condition_number, normalize_columns};
use crate::params::{self, unit, Model, Params, Unit, NAMES, N_PARAMS};
use lm::{Final, Keep, Lm, Normal, State};
use nalgebra::{DMatrix, DVector, SMatrix};
use rows::{dependency, reduced_jacobian, Columns, Key, Problem};
use select::{auto_select, effect_observability, prior_of, scaling_vector, select_geometric};
use shared::View;
use std::cell::OnceCell;
use std::collections::HashSet;
use uncertainty::{posterior, step2_covariance, Posterior, KEEP_JACOBIAN_POSES};

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
        use params::{L4, L5, XA4R, XA5R, XB4R, XB5R, YA4R, YA5R, YB4R, YB5R};
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
    /// Threads the rows are evaluated on (0: every core). The result is the same to the bit
    /// on any number: the rows are summed in fixed pieces, in order.
    pub threads: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            model: Model::M29,
            selection: Selection::Prior(Prior::default()),
            links: Vec::new(),
            scaling: Scaling::ColumnNorm,
            outlier_sigma: Some(3.0),
            // a model far from the data (a missing effect of 10⁷ χ², what a diagnosis meets)
            // takes the LM longer; a good one stops in a handful
            max_iterations: 400,
            noise: NoiseModel::default(),
            threads: 0,
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
    #[error("{campaign}: the effects were bound to a campaign of {bound} poses, not to this one of {poses}")]
    EffectsOfAnotherCampaign {
        campaign: String,
        bound: usize,
        poses: usize,
    },
    #[error("{given} starting effect parameters given, the effects have {expected} (or give none: all zero)")]
    StartThetaLength { given: usize, expected: usize },
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
    #[error("{campaign}:{line} ({instrument}): the pose's model-minus-measurement is not finite ({value}); its readings are beyond any machine")]
    NonFiniteRow {
        campaign: String,
        line: usize,
        instrument: &'static str,
        value: f64,
    },
    #[error("the calibration's result is not a number: {0} (the rows carry non-finite values or weights)")]
    NonFinite(String),
    /// Its caller's observer asked it to stop ([`Flow::Stop`]): no result.
    #[error("the calibration was cancelled by its caller")]
    Cancelled,
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
    /// mm, or rad for ψ, or N for a drive force.
    pub rms_before: f64,
    pub rms_after: f64,
    pub is_angle: bool,
    /// A drive force (N).
    pub is_force: bool,
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
    pub effect: String,
    pub name: String,
    pub unit: String,
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
    /// Whether the LM stopped after one confirmed screening step from a warm start instead
    /// of converging ([`WarmStart::screen`]).
    pub screened: bool,
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
    pub residuals: Vec<RowValue>,
    pub leverage: Vec<f64>,
    /// Posterior covariance of the 29 parameters (mm, rad, scaled by the variance factor as
    /// the σ of `identified`), with the correlations the campaign left between them: a
    /// campaign pins combinations, and the σ alone would let a later estimator (the online
    /// tracker) move what the campaign had pinned. Rows and columns of parameters not
    /// identified are zero (held at their start value).
    pub covariance: SMatrix<f64, N_PARAMS, N_PARAMS>,
}

/// Where the LM starts when not at the start parameters: the fit of a neighbouring model.
/// The start parameters stay the prior's centre and the "before" of the report; only the
/// path changes (the diagnosis starts each candidate at the current model's fit, two or
/// three steps from its own minimum instead of five).
#[derive(Clone, Copy, Debug)]
pub struct WarmStart<'a> {
    pub params: &'a Params,
    /// The effects' parameters (as many as the effects have).
    pub theta: &'a [f64],
    /// Stop after the first step if the rows confirm it (the LM's predicted reduction
    /// realised within 2 %): from the neighbour's minimum that is the Gauss-Newton step of
    /// the linearised problem, what the diagnosis screens its candidates with. Where the
    /// step is not confirmed the fit goes on to convergence as without it.
    pub screen: bool,
}

/// One fit as `req` asks, its rows weighted by `req.options.noise` (the noise rounds of
/// [`Noise::Estimate`] make one each), with the rows at the start and the warm start read
/// from `req.shared` where they are there.
fn fit_once(req: &Request) -> Result<Calibration, CalibrationError> {
    let Request {
        campaign,
        start,
        options: opts,
        effects,
        theta0,
        warm,
        shared,
        progress,
        ..
    } = *req;
    let theta0 = start_theta(campaign, opts, effects, theta0)?;
    let pb = Problem::new(campaign, *start, effects, opts);
    let init = match warm {
        Some(w) => State {
            p: *w.params,
            theta: start_theta(campaign, opts, effects, w.theta)?,
        },
        None => State {
            p: *start,
            theta: theta0.clone(),
        },
    };
    // rows shared with other calibrations serve a warm start only (a cold one starts from
    // the plan's)
    let view = shared
        .filter(|_| warm.is_some())
        .and_then(|s| s.view(&pb, &theta0, &init));
    let mut plan = Plan::new(&pb, &theta0, warm.is_none(), view.as_ref())?;
    let (fit, last) = step1(
        &pb,
        &plan,
        init,
        (warm.is_some(), warm.is_some_and(|w| w.screen)),
        view.as_ref(),
        progress,
    )?;
    // the corrections at the fit's θ: only a large campaign's leverages and step 2 read them
    let corr = OnceCell::new();
    let corr = || corr.get_or_init(|| effects.corrections(&fit.state.theta));
    let (rows_final, post) = posterior(&pb, &plan, (&fit.state.p, &corr, &fit.drop), last)?;
    // chi-square of the measurements themselves (not the prior, nor the virtual rows of step 2)
    let chi2: f64 = rows_final.iter().map(|r| (r.value / r.sigma).powi(2)).sum();
    let chi2_per_dof = chi2 / (rows_final.len() as f64 - post.dof_model).max(1.0);
    let s1 = Step1Report::new(&pb, &plan, &fit.state, &post, chi2_per_dof.max(1.0));
    let mut table = step1_table(&pb, &mut plan, &fit.drop, &rows_final)?;
    let mut identified = s1.identified;
    let mut iterations = fit.iterations;
    let mut p = fit.state.p;
    // symmetric to the bit: the inverse's round-off is not the campaign's
    let mut covariance = SMatrix::<f64, N_PARAMS, N_PARAMS>::from_fn(|i, j| {
        0.5 * (s1.cov_p1[(i, j)] + s1.cov_p1[(j, i)])
    });
    if let Some(s2) = step2(&pb, &plan, &fit, &corr, &s1.cov_p1, progress)? {
        p = s2.p;
        iterations += s2.iterations;
        s2.widen(&mut covariance);
        identified.extend(s2.identified);
        table.before(s2.before_rows.iter().map(RowValue::from));
        table.after(s2.after_rows.iter().map(RowValue::from));
    }
    check_finite(&identified, &s1.effects, chi2_per_dof)?;
    Ok(Calibration {
        model: opts.model,
        start: *start,
        params: p,
        identified,
        iterations,
        screened: fit.screened,
        condition_number: plan.condition,
        outliers: fit.outliers,
        rms: table.finish(),
        cost_before: table.cost_before,
        cost_after: table.cost_after,
        chi2_per_dof,
        rows: table.rows,
        effects: s1.effects,
        theta: fit.state.theta,
        n_identified: plan.ids.len() + plan.free_theta.len(),
        dof_model: post.dof_model,
        determined: post.determined,
        residuals: rows_final,
        leverage: post.leverage,
        covariance,
    })
}

/// The RMS table of step 1: its final rows, and the rows at the start, which are the plan's
/// unless outliers (`drop`) were dropped since.
fn step1_table(
    pb: &Problem,
    plan: &mut Plan,
    drop: &HashSet<Key>,
    rows_final: &[RowValue],
) -> Result<report::RmsTable, CalibrationError> {
    let mut table = report::RmsTable::default();
    table.after(rows_final.iter().cloned());
    let before = if drop.is_empty() {
        std::mem::take(&mut plan.before)
    } else {
        let start = &pb.start;
        pb.map_pieces(
            Step::Direct,
            start,
            start,
            plan.corr0(pb),
            drop,
            before_table,
        )?
    };
    for t in before {
        table.merge(t);
    }
    Ok(table)
}

/// A calibration whose values, uncertainties or χ² are not finite is refused, naming what:
/// a solver reports an implausible result instead of returning it.
fn check_finite(
    identified: &[Identified],
    effects: &[EffectEstimate],
    chi2_per_dof: f64,
) -> Result<(), CalibrationError> {
    if !chi2_per_dof.is_finite() {
        return Err(CalibrationError::NonFinite(format!(
            "chi2/dof {chi2_per_dof}"
        )));
    }
    let bad = identified
        .iter()
        .filter(|i| !(i.value.is_finite() && i.sigma.is_finite()))
        .map(|i| format!("{} = {} ± {}", i.name, i.value, i.sigma))
        .chain(
            effects
                .iter()
                .filter(|e| !(e.value.is_finite() && e.sigma.is_finite()))
                .map(|e| format!("{}.{} = {} ± {}", e.effect, e.name, e.value, e.sigma)),
        )
        .collect::<Vec<_>>();
    if bad.is_empty() {
        Ok(())
    } else {
        Err(CalibrationError::NonFinite(bad.join(", ")))
    }
}

/// The effect parameters to start from (`theta0`, all zero when it is empty; any other
/// length is an error), after checking that the options and the effects fit the campaign.
fn start_theta(
    campaign: &Campaign,
    opts: &Options,
    effects: &EffectSet,
    theta0: &[f64],
) -> Result<Vec<f64>, CalibrationError> {
    if let Selection::List(list) = &opts.selection {
        if let Some(&i) = list.iter().find(|&&i| !opts.model.has_param(i)) {
            return Err(CalibrationError::NotInModel(NAMES[i], opts.model));
        }
    }
    if !effects.fits_campaign_of(campaign.poses.len()) {
        return Err(CalibrationError::EffectsOfAnotherCampaign {
            campaign: campaign.source.clone(),
            bound: effects.n_poses(),
            poses: campaign.poses.len(),
        });
    }
    match theta0.len() {
        0 => Ok(vec![0.0; effects.n_params()]),
        n if n == effects.n_params() => Ok(theta0.to_vec()),
        given => Err(CalibrationError::StartThetaLength {
            given,
            expected: effects.n_params(),
        }),
    }
}

/// What step 1 identifies and how, decided once from the rows at the start parameters.
struct Plan {
    /// θ₀ and the effects' corrections there (the "before" of the report, and the LM's
    /// where it evaluates at θ₀), made when first read: a plan from shared rows needs none.
    theta0: Vec<f64>,
    corr0: OnceCell<Corrections>,
    /// Geometric parameters of step 1, and the rod-2 parameters wanted from step 2.
    ids: Vec<usize>,
    step2_wanted: Vec<usize>,
    /// The prior's (parameter, tolerance) of step 1 (empty without a prior).
    prior: Vec<(usize, f64)>,
    /// Scaling of the geometric parameters; condition number of their column-normalised
    /// Jacobian.
    h: DVector<f64>,
    condition: f64,
    /// Effect parameters identified, their scaling, and every effect parameter's
    /// observability.
    free_theta: Vec<usize>,
    h_theta: DVector<f64>,
    observability: Vec<f64>,
    /// Rows at the start (the cap on outliers is a share of them).
    n_rows0: usize,
    /// Their RMS table per piece: the report's "before" (taken once it is used).
    before: Vec<report::RmsTable>,
    /// Their normal equations in the unknowns, unscaled and without the prior, for a cold
    /// start (the LM starts at the start): it starts from these.
    normal0: Option<Normal>,
}

impl Plan {
    /// The effects' corrections at θ₀, made the first time they are read.
    fn corr0(&self, pb: &Problem) -> &Corrections {
        self.corr0
            .get_or_init(|| pb.effects.corrections(&self.theta0))
    }

    fn new(
        pb: &Problem,
        theta0: &[f64],
        cold: bool,
        shared: Option<&View>,
    ) -> Result<Plan, CalibrationError> {
        let opts = pb.opts;
        let corr0 = OnceCell::new();
        let source = if let Some(view) = shared {
            Source::Shared(view)
        } else {
            Source::Evaluated(corr0.get_or_init(|| pb.effects.corrections(theta0)))
        };
        let start = StartRows::of(pb, source, cold)?;
        let linked: HashSet<usize> = opts.links.iter().map(|l| l.param).collect();
        let (ids, step2_wanted) = select_geometric(pb.campaign, &start.columns, opts, &linked)?;
        let prior = prior_of(&opts.selection, &ids);
        if prior.is_empty() && start.n_rows < ids.len() {
            return Err(CalibrationError::Underdetermined {
                params: ids.len(),
                rows: start.n_rows,
            });
        }
        let layout = pb.effects.layout();
        let observability = effect_observability(&start.columns, &ids, &opts.links, pb.effects);
        let free_theta: Vec<usize> = (0..pb.effects.n_params())
            .filter(|&k| !pb.effects.is_held(k))
            .filter(|&k| {
                let (frac, signal) = observability[k];
                frac >= MIN_EFFECT_OBSERVABILITY
                    && signal * layout[k].param.prior >= MIN_EFFECT_SIGNAL
            })
            .collect();
        let h_theta = DVector::from_iterator(
            free_theta.len(),
            free_theta.iter().map(|&k| layout[k].param.prior),
        );
        let jr0 = start.columns.reduced(&ids, &opts.links);
        let normal0 = start
            .normal
            .as_ref()
            .map(|all| reduced_normal(all, &ids, &opts.links, &free_theta));
        Ok(Plan {
            normal0,
            theta0: theta0.to_vec(),
            corr0,
            h: scaling_vector(&jr0, &ids, opts.scaling)?,
            condition: condition_number(&normalize_columns(&jr0)),
            ids,
            step2_wanted,
            prior,
            free_theta,
            h_theta,
            observability: observability.iter().map(|o| o.0).collect(),
            n_rows0: start.n_rows,
            before: start.before,
        })
    }
}

/// What the plan reads from the rows at the start parameters, piece by piece: how many, and
/// their columns.
struct StartRows {
    n_rows: usize,
    columns: Columns,
    /// Their normal equations in all 29 + k columns, unscaled: summed as the LM sums its
    /// own (the same products, pieces in order), so that its start from them is the start
    /// it would evaluate; only for a cold start (a warm one starts elsewhere).
    normal: Option<Normal>,
    /// Each piece's RMS table (the report's "before": the same rows).
    before: Vec<report::RmsTable>,
}

/// The "before" RMS table of one piece's rows.
fn before_table(rows: &[Residual]) -> report::RmsTable {
    let mut t = report::RmsTable::default();
    t.before(rows.iter().map(RowValue::from));
    t
}

impl StartRows {
    fn of(pb: &Problem, source: Source, cold: bool) -> Result<StartRows, CalibrationError> {
        let n_theta = pb.effects.n_params();
        let each = |rows: &[Residual]| {
            // a row whose squared weighted value overflows makes the cost infinite
            let bad = rows
                .iter()
                .find(|r| !(r.value / r.sigma).powi(2).is_finite())
                .map(|r| (r.pose, r.value));
            // the block's Jacobian once, for its normal equations and its R factor
            let j = rows::all_columns(rows, n_theta);
            let normal = cold.then(|| Normal::of(&j, &rows::weighted_values(rows)));
            (
                rows.len(),
                bad,
                Columns::factor(j),
                (before_table(rows), normal),
            )
        };
        let pieces = match source {
            Source::Evaluated(corr0) => {
                let none = HashSet::new();
                pb.map_pieces(Step::Direct, &pb.start, &pb.start, corr0, &none, each)?
            }
            Source::Shared(view) => view.map(view.at_start, each),
        };
        if let Some((pose, value)) = pieces.iter().find_map(|p| p.1) {
            let pose = &pb.campaign.poses[pose];
            return Err(CalibrationError::NonFiniteRow {
                campaign: pb.campaign.source.clone(),
                line: pose.line,
                instrument: pose.instrument.as_str(),
                value,
            });
        }
        let n_rows = pieces.iter().map(|p| p.0).sum();
        if n_rows == 0 {
            return Err(CalibrationError::NoMeasurements(pb.campaign.source.clone()));
        }
        let normal = cold.then(|| {
            let mut sum = Normal::zeros(N_PARAMS + n_theta);
            for part in pieces.iter().filter_map(|p| p.3 .1.as_ref()) {
                sum.add(part);
            }
            sum
        });
        let (factors, before) = pieces.into_iter().map(|p| (p.2, p.3 .0)).unzip();
        let columns = Columns::combine(factors, n_theta);
        Ok(StartRows {
            n_rows,
            columns,
            normal,
            before,
        })
    }
}

/// Where the rows at the start come from: evaluated with the effects' corrections there, or
/// read from rows shared with other calibrations.
#[derive(Clone, Copy)]
enum Source<'a> {
    Evaluated(&'a Corrections),
    Shared(&'a View<'a>),
}

/// Normal equations in all 29 + k columns (`all`) reduced to the unknowns: the parameters
/// `ids` under `links`, then the effect parameters `free` (Dᵀ A D with D's entries 0 and
/// 1 where nothing is linked: the reduced equations are the same numbers).
fn reduced_normal(all: &Normal, ids: &[usize], links: &[Link], free: &[usize]) -> Normal {
    let (n, cols) = (ids.len(), all.g.len());
    let mut d = DMatrix::zeros(cols, n + free.len());
    d.view_mut((0, 0), (N_PARAMS, n))
        .copy_from(&dependency(ids, links));
    for (k, &f) in free.iter().enumerate() {
        d[(N_PARAMS + f, n + k)] = 1.0;
    }
    Normal {
        a: d.tr_mul(&all.a) * &d,
        g: d.tr_mul(&all.g),
        cost: all.cost,
    }
}

/// Step 1's fit: the unknowns, the rows dropped as outliers, the LM's iterations.
struct Step1Fit {
    state: State,
    iterations: usize,
    /// The LM stopped after a confirmed screening step (see [`WarmStart::screen`]).
    screened: bool,
    drop: HashSet<Key>,
    outliers: Vec<Outlier>,
}

/// Step 1 with outlier elimination rounds (eq. 3.31-3.32): fit, drop the rows beyond
/// `outlier_sigma`, fit again, while new outliers appear and fewer than 5 % are dropped.
/// With the fit, the rows it ended with (the LM's last evaluation: the posterior's rows).
fn step1(
    pb: &Problem,
    plan: &Plan,
    init: State,
    (warm, screen): (bool, bool),
    shared: Option<&View>,
    progress: Option<Observer>,
) -> Result<(Step1Fit, Final), CalibrationError> {
    let opts = pb.opts;
    let mut fit = Step1Fit {
        state: init,
        iterations: 0,
        screened: false,
        drop: HashSet::new(),
        outliers: Vec::new(),
    };
    // a small campaign keeps its final rows' Jacobian for the leverages
    let keep = if pb.campaign.poses.len() <= KEEP_JACOBIAN_POSES {
        Keep::Jacobians
    } else {
        Keep::Nothing
    };
    let last = loop {
        // the first run starts where the plan's rows (or the shared ones) were evaluated:
        // the start (cold) or the warm start, θ₀, nothing dropped
        let first = fit.drop.is_empty() && fit.iterations == 0;
        let lm = Lm {
            problem: pb,
            step: Step::Direct,
            p_cal: pb.start,
            drop: &fit.drop,
            d: dependency(&plan.ids, &opts.links),
            h: plan.h.clone(),
            free_theta: &plan.free_theta,
            h_theta: plan.h_theta.clone(),
            max_iterations: opts.max_iterations,
            screen,
            warm,
            prior: plan.prior.clone(),
            center: pb.start,
            keep,
            initial: (!warm && first).then(|| plan.normal0.clone()).flatten(),
            // the first run at a warm start reads its start from shared rows, if any
            shared: shared.filter(|_| warm && first),
            made: shared
                .is_none()
                .then(|| (plan.theta0.as_slice(), plan.corr0(pb))),
        };
        let res = lm.run(&fit.state, progress)?;
        fit.state = res.state;
        fit.iterations += res.iterations;
        fit.screened = res.screened;
        // the rows the LM ended with (evaluated once more where it kept none): the outlier
        // test's and the posterior's
        let last = match res.last {
            Some(last) => last,
            None => lm.final_rows(&fit.state)?,
        };
        let found = opts
            .outlier_sigma
            .map(|k| report::find_outliers(&last.rows, pb.campaign, k));
        let Some(found) = found else { break last };
        if found.is_empty() || fit.outliers.len() > plan.n_rows0 / 20 {
            break last;
        }
        for (key, o) in found {
            fit.drop.insert(key);
            fit.outliers.push(o);
        }
    };
    Ok((fit, last))
}

/// Step 1's parameters with their uncertainties (scaled by the variance factor `s2`), and
/// the covariance of the 29 parameters step 2 inherits.
struct Step1Report {
    identified: Vec<Identified>,
    effects: Vec<EffectEstimate>,
    cov_p1: DMatrix<f64>,
}

impl Step1Report {
    fn new(pb: &Problem, plan: &Plan, x: &State, post: &Posterior, s2: f64) -> Step1Report {
        let cov1 = &post.cov1 * s2;
        let d1 = dependency(&plan.ids, &pb.opts.links);
        let identified = plan
            .ids
            .iter()
            .enumerate()
            .map(|(k, &i)| Identified {
                name: NAMES[i],
                index: i,
                nominal: pb.start[i],
                value: x.p[i],
                sigma: cov1[(k, k)].max(0.0).sqrt(),
                step: 1,
            })
            .collect();
        let effects = pb
            .effects
            .layout()
            .iter()
            .enumerate()
            .map(|(k, slot)| {
                let free = plan.free_theta.iter().position(|&f| f == k);
                EffectEstimate {
                    effect: slot.effect.clone(),
                    name: slot.param.name.clone(),
                    unit: slot.param.unit.clone(),
                    value: x.theta[k],
                    sigma: free.map_or(0.0, |f| post.sig_theta[f] * s2.sqrt()),
                    observability: plan.observability[k],
                    identified: free.is_some(),
                    prior: slot.param.prior,
                }
            })
            .collect();
        Step1Report {
            identified,
            effects,
            cov_p1: &d1 * &cov1 * d1.transpose(),
        }
    }
}

/// What step 2 adds: rod 2's parameters and its rows before and after.
struct Step2Fit {
    p: Params,
    iterations: usize,
    identified: Vec<Identified>,
    before_rows: Vec<Residual>,
    after_rows: Vec<Residual>,
    /// Covariance of step 2's parameters, and with the 29 of step 1 (see
    /// [`uncertainty::step2_covariance`]).
    cov: DMatrix<f64>,
    cross: DMatrix<f64>,
}

impl Step2Fit {
    /// Step 1's 29 × 29 covariance with step 2's parameters in it: their own block and their
    /// covariance with step 1's (step 2 re-identifies parameters step 1 held).
    fn widen(&self, cov: &mut SMatrix<f64, N_PARAMS, N_PARAMS>) {
        let ids: Vec<usize> = self.identified.iter().map(|id| id.index).collect();
        for (a, &i) in ids.iter().enumerate() {
            for j in 0..N_PARAMS {
                cov[(i, j)] = self.cross[(a, j)];
                cov[(j, i)] = self.cross[(a, j)];
            }
        }
        for (a, &i) in ids.iter().enumerate() {
            for (b, &j) in ids.iter().enumerate() {
                cov[(i, j)] = self.cov[(a, b)];
            }
        }
    }
}

/// Step 2: rod 2 from virtual measurements of the forward instruments (eq. 4.32), made with
/// step 1's parameters; None when the campaign has no forward instrument or nothing to
/// identify there.
fn step2<'c>(
    pb: &Problem,
    plan: &Plan,
    fit: &Step1Fit,
    corr: &dyn Fn() -> &'c Corrections,
    cov_p1: &DMatrix<f64>,
    progress: Option<Observer>,
) -> Result<Option<Step2Fit>, CalibrationError> {
    if plan.step2_wanted.is_empty() {
        return Ok(None);
    }
    let corr = corr();
    let opts = pb.opts;
    let p1 = fit.state.p;
    // the virtual q2 rows at p, their virtual measurements made with step 1's p1
    let virtual_rows = |p: &Params| pb.rows(Step::VirtualQ2, p, &p1, corr, &fit.drop);
    let rows2 = virtual_rows(&p1)?;
    let ids2 = match &opts.selection {
        Selection::Auto { max_condition } => auto_select(
            &Columns::of(&rows2, 0),
            &plan.step2_wanted,
            &[],
            *max_condition,
        ),
        Selection::List(_) | Selection::Prior(_) => plan.step2_wanted.clone(),
    };
    if ids2.is_empty() {
        return Ok(None);
    }
    let prior2 = prior_of(&opts.selection, &ids2);
    let jr2 = reduced_jacobian(&rows2, &ids2, &[]);
    let lm = Lm {
        problem: pb,
        step: Step::VirtualQ2,
        p_cal: p1,
        drop: &fit.drop,
        d: dependency(&ids2, &[]),
        h: scaling_vector(&jr2, &ids2, opts.scaling)?,
        // the effects stay in the rows at their identified values
        free_theta: &[],
        h_theta: DVector::zeros(0),
        max_iterations: opts.max_iterations,
        screen: false,
        warm: false,
        prior: prior2.clone(),
        center: pb.start,
        keep: Keep::Nothing,
        initial: None,
        shared: None,
        made: None,
    };
    let res = lm.run(&fit.state, progress)?;
    let p = res.state.p;
    let after_rows = virtual_rows(&p)?;
    let (cov, cross) = step2_covariance(&after_rows, &ids2, &prior2, cov_p1)?;
    let identified = ids2
        .iter()
        .enumerate()
        .map(|(k, &i)| Identified {
            name: NAMES[i],
            index: i,
            nominal: pb.start[i],
            value: p[i],
            sigma: cov[(k, k)].max(0.0).sqrt(),
            step: 2,
        })
        .collect();
    let before_rows = pb.rows(
        Step::VirtualQ2,
        &pb.start,
        &pb.start,
        plan.corr0(pb),
        &fit.drop,
    )?;
    Ok(Some(Step2Fit {
        p,
        iterations: res.iterations,
        identified,
        before_rows,
        after_rows,
        cov,
        cross,
    }))
}
