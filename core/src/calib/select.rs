//! Which unknowns a calibration identifies: the geometric parameters of step 1 and step 2
//! (observability order, explicit list, or all of them under the tolerance prior), their
//! scaling, and the effect parameters the campaign can tell from the geometry.

use super::rows::Columns;
use super::types::{CalibrationError, Link, Options, Scaling, Selection};
use crate::campaign::Campaign;
use crate::effects::EffectSet;
use crate::obs;
use crate::observability::{normalize_columns, qr_pivot_order};
use crate::params::{self, variation_range, NAMES, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::HashSet;

/// Fraction of an effect parameter's signature that the geometric columns (and the effect
/// columns before it) cannot mimic, below which it is held: numerically absorbed.
pub const MIN_EFFECT_OBSERVABILITY: f64 = 1e-6;
/// Size of that unmimicked signature for a parameter at its prior magnitude, in units of the
/// measurements' σ (root of its χ² contribution), below which it is held: a prior-sized value
/// would not move the fit by one standard deviation.
pub const MIN_EFFECT_SIGNAL: f64 = 1.0;

/// Parameters of `candidates` in observability order, kept while the condition number of
/// the column-normalised Jacobian stays below `max_condition`.
pub(super) fn auto_select(
    columns: &Columns,
    candidates: &[usize],
    links: &[Link],
    max_condition: f64,
) -> Vec<usize> {
    let jr = columns.reduced(candidates, links);
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

pub(super) fn scaling_vector(
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

/// Rod-2 parameters: identified by the virtual q2 step of forward instruments.
fn rod2_params() -> [usize; 5] {
    use params::{L2, XA2R, XB2R, YA2R, YB2R};
    [L2, XA2R, YA2R, XB2R, YB2R]
}

/// The prior's (parameter, tolerance) of each of `ids`; empty without a prior.
pub(super) fn prior_of(selection: &Selection, ids: &[usize]) -> Vec<(usize, f64)> {
    match selection {
        Selection::Prior(prior) => ids.iter().map(|&i| (i, prior.sigma(i))).collect(),
        _ => Vec::new(),
    }
}

/// Step 1's identified geometric parameters, and the rod-2 parameters wanted from step 2.
pub(super) fn select_geometric(
    campaign: &Campaign,
    columns0: &Columns,
    opts: &Options,
    linked: &HashSet<usize>,
) -> Result<(Vec<usize>, Vec<usize>), CalibrationError> {
    let model = opts.model;
    // Candidates of step 1: the model's free parameters with an influence on the direct rows.
    let j0 = columns0.geometric();
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
            auto_select(columns0, &cands, &opts.links, *max_condition)
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
/// outside part (σ units per unit of the parameter), and the norm of the whole column.
pub(super) fn effect_observability(
    columns: &Columns,
    ids: &[usize],
    links: &[Link],
    effects: &EffectSet,
) -> Vec<(f64, f64, f64)> {
    let n = effects.n_params();
    if n == 0 {
        return Vec::new();
    }
    let jg = normalize_columns(&columns.reduced(ids, links));
    let all: Vec<usize> = (0..n).collect();
    let jt = columns.theta(&all);
    let mut basis: Vec<DVector<f64>> = Vec::new();
    let add = |v: DVector<f64>, basis: &mut Vec<DVector<f64>>| -> (f64, f64, f64) {
        let norm0 = v.norm();
        if !(norm0 > 0.0) {
            return (0.0, 0.0, 0.0);
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
        (rest / norm0, rest, norm0)
    };
    for k in 0..jg.ncols() {
        add(jg.column(k).into_owned(), &mut basis);
    }
    (0..n)
        .map(|k| add(jt.column(k).into_owned(), &mut basis))
        .collect()
}
