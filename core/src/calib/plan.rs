//! What step 1 identifies and how, decided once from the rows at the start parameters.

use super::lm::Normal;
use super::report;
use super::rows;
use super::rows::{dependency, Columns, Problem};
use super::select::{effect_observability, prior_of, scaling_vector, select_geometric};
use super::select::{MIN_EFFECT_OBSERVABILITY, MIN_EFFECT_SIGNAL};
use super::shared::View;
use super::types::{CalibrationError, Link};
use crate::effects::Corrections;
use crate::obs::{Residual, RowValue, Step};
use crate::observability::{condition_number, normalize_columns};
use crate::params::N_PARAMS;
use nalgebra::{DMatrix, DVector};
use std::cell::OnceCell;
use std::collections::HashSet;

/// What step 1 identifies and how, decided once from the rows at the start parameters.
pub(super) struct Plan {
    /// θ₀ and the effects' corrections there (the "before" of the report, and the LM's
    /// where it evaluates at θ₀), made when first read: a plan from shared rows needs none.
    pub(super) theta0: Vec<f64>,
    pub(super) corr0: OnceCell<Corrections>,
    /// Geometric parameters of step 1, and the rod-2 parameters wanted from step 2.
    pub(super) ids: Vec<usize>,
    pub(super) step2_wanted: Vec<usize>,
    /// The prior's (parameter, tolerance) of step 1 (empty without a prior).
    pub(super) prior: Vec<(usize, f64)>,
    /// Scaling of the geometric parameters; condition number of their column-normalised
    /// Jacobian.
    pub(super) h: DVector<f64>,
    pub(super) condition: f64,
    /// Effect parameters identified, their scaling, and every effect parameter's
    /// observability.
    pub(super) free_theta: Vec<usize>,
    pub(super) h_theta: DVector<f64>,
    /// The anchored effect parameters' priors: (index among the free ones, σ).
    pub(super) theta_prior: Vec<(usize, f64)>,
    pub(super) observability: Vec<f64>,
    /// Why each effect parameter is not fitted (None: it is).
    pub(super) why_held: Vec<Option<String>>,
    /// Rows at the start (the cap on outliers is a share of them).
    pub(super) n_rows0: usize,
    /// Their RMS table per piece: the report's "before" (taken once it is used).
    pub(super) before: Vec<report::RmsTable>,
    /// Their normal equations in the unknowns, unscaled and without the prior, for a cold
    /// start (the LM starts at the start): it starts from these.
    pub(super) normal0: Option<Normal>,
}

impl Plan {
    /// The effects' corrections at θ₀, made the first time they are read.
    pub(super) fn corr0(&self, pb: &Problem) -> &Corrections {
        self.corr0
            .get_or_init(|| pb.effects.corrections(&self.theta0, &pb.start))
    }

    pub(super) fn new(
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
            Source::Evaluated(corr0.get_or_init(|| pb.effects.corrections(theta0, &pb.start)))
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
        let why_held = why_held(pb, &observability);
        let free_theta: Vec<usize> = (0..pb.effects.n_params())
            .filter(|&k| why_held[k].is_none())
            .collect();
        let h_theta = DVector::from_iterator(
            free_theta.len(),
            free_theta.iter().map(|&k| layout[k].param.prior),
        );
        let theta_prior: Vec<(usize, f64)> = free_theta
            .iter()
            .enumerate()
            .filter_map(|(f, &k)| layout[k].param.anchor.map(|s| (f, s)))
            .collect();
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
            theta_prior,
            observability: observability.iter().map(|o| o.0).collect(),
            why_held,
            n_rows0: start.n_rows,
            before: start.before,
        })
    }
}

/// Why each effect parameter is not fitted (None: it is): held, or moving nothing the
/// geometry does not absorb at its start. An anchored one is always fitted: its prior
/// determines it where the rows do not.
fn why_held(pb: &Problem, observability: &[(f64, f64, f64)]) -> Vec<Option<String>> {
    let opts = pb.opts;
    let layout = pb.effects.layout();
    (0..pb.effects.n_params())
        .map(|k| {
            if pb.effects.is_held(k) {
                return Some("held at zero: a part the data do not support".to_owned());
            }
            if layout[k].param.anchor.is_some() {
                // its prior determines it where the rows do not
                return None;
            }
            let (frac, signal, whole) = observability[k];
            let param = &layout[k].param;
            let size = signal * param.prior * opts.noise_inflation.max(1.0);
            if !(whole > 0.0) {
                Some(format!(
                    "no sensitivity at its start {} {} (give it a start: where it moves \
                     the model)",
                    param.start, param.unit
                ))
            } else if frac < MIN_EFFECT_OBSERVABILITY {
                Some("the campaign cannot tell it from the geometry".to_owned())
            } else if size < MIN_EFFECT_SIGNAL {
                Some(format!(
                    "at its prior {} {} it would move the rows by {size:.2} σ beyond what \
                     the geometry absorbs, less than one",
                    param.prior, param.unit
                ))
            } else {
                None
            }
        })
        .collect()
}

/// What the plan reads from the rows at the start parameters, piece by piece: how many, and
/// their columns.
pub(super) struct StartRows {
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
pub(super) fn before_table(rows: &[Residual]) -> report::RmsTable {
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
pub(super) enum Source<'a> {
    Evaluated(&'a Corrections),
    Shared(&'a View<'a>),
}

/// Normal equations in all 29 + k columns (`all`) reduced to the unknowns: the parameters
/// `ids` under `links`, then the effect parameters `free` (Dᵀ A D with D's entries 0 and
/// 1 where nothing is linked: the reduced equations are the same numbers).
pub(super) fn reduced_normal(
    all: &Normal,
    ids: &[usize],
    links: &[Link],
    free: &[usize],
) -> Normal {
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
