//! What a lagged thermometer's own noise leaves in the residual. A model that reads a
//! thermometer's rate (`thermal_lag`, a written `rate()` or `lag()`) turns the readings'
//! noise into an error of the parts' temperature that is smooth in time: the rate is a fit
//! over a window of minutes, and its error, times a time constant of minutes, is a few
//! hundredths of a kelvin that wander with the window. The self-calibration's encoder
//! resolves it: with the twin's readings free of noise, the same model leaves no structure.
//! That structure is the thermometer's, not a missing effect's, and the structure tests read
//! the residual without it: the part of the residual that a smooth error of the readings
//! (Legendre polynomials in time, two per half-width of the rate's window) makes through the
//! model as fitted is taken out, by least squares in each row's noise, before the tests.
//! The rate's error wanders on the scale of the window's half-width; a basis follows a
//! wander of that width with two terms to it (as a signal is sampled at twice its highest
//! frequency). With one per half-width, 5 of the benchmark's 36 lagging thermometers ended
//! `unexplained_structure` (4 within 1.05x the held-out floor); with two, 3 (2 at the floor,
//! both `nothing_missing` with their readings made clean).

use crate::campaign::Campaign;
use crate::effects::{memory, Effect, EffectSet};
use crate::noise::NoiseModel;
use crate::obs::{self, Direction, Form, RowValue, Step};
use crate::params::{Model, Params};
use std::collections::HashMap;

/// The size of the readings' change each term is measured with (K): far below any
/// thermometer's noise, so that the rate's fit chooses the same window, far above the
/// rows' round-off.
const PROBE_K: f64 = 1e-6;

/// The model as fitted whose rows the thermometers' noise moves.
pub(crate) struct Fitted<'a> {
    pub effects: &'a [&'a dyn Effect],
    pub params: &'a Params,
    pub theta: &'a [f64],
    pub model: Model,
    pub noise: &'a NoiseModel,
}

/// How much of the residual the thermometers' smooth error takes, where the model reads a
/// thermometer's history.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Carried {
    /// The thermometer columns, and the terms each took out.
    pub columns: Vec<(String, usize)>,
    /// The share of the residual's χ² they took (0..1).
    pub share: f64,
}

/// The residual `rows` without the part a smooth error of each thermometer column makes
/// through `fitted`, and what was taken; None where no effect of the model reads a
/// thermometer's history, or the rows cannot be evaluated again.
pub(crate) fn without_carried(
    campaign: &Campaign,
    fitted: &Fitted,
    rows: &[RowValue],
) -> Option<(Vec<RowValue>, Carried)> {
    if !fitted.effects.iter().any(|e| e.has_memory()) {
        return None;
    }
    let base = evaluate(campaign, fitted)?;
    let at: HashMap<(usize, Direction), usize> = rows
        .iter()
        .enumerate()
        .map(|(k, r)| ((r.pose, r.direction), k))
        .collect();
    let mut terms: Vec<Vec<f64>> = Vec::new();
    let mut columns = Vec::new();
    for (c, name) in campaign.covariate_names.iter().enumerate() {
        if !name.starts_with("temp_") {
            continue;
        }
        let Some(basis) = basis(campaign, c) else {
            continue;
        };
        let before = terms.len();
        for phi in &basis {
            let moved = probed(campaign, c, phi);
            let Some(after) = evaluate(&moved, fitted) else {
                continue;
            };
            terms.push(term(&base, &after, &at, rows)?);
        }
        columns.push((name.clone(), terms.len() - before));
    }
    let (left, share) = project_out(rows, &terms)?;
    Some((left, Carried { columns, share }))
}

/// The model's rows of `campaign` (mm or rad, each with its key).
fn evaluate(campaign: &Campaign, fitted: &Fitted) -> Option<Vec<((usize, Direction), f64)>> {
    let start = Params::nominal();
    let set = EffectSet::bind(fitted.effects, campaign, &start).ok()?;
    let corr = set.corrections(fitted.theta, fitted.params);
    let rows = obs::residuals_in(
        campaign,
        fitted.params,
        fitted.model,
        Step::Direct,
        &start,
        &corr,
        fitted.noise,
        Form::Decorrelated,
    )
    .ok()?;
    Some(
        rows.iter()
            .map(|r| ((r.pose, r.direction), r.value))
            .collect(),
    )
}

/// One term in `rows`' order, each row in its noise: the change of the model's rows per
/// kelvin of the probe.
fn term(
    base: &[((usize, Direction), f64)],
    after: &[((usize, Direction), f64)],
    at: &HashMap<(usize, Direction), usize>,
    rows: &[RowValue],
) -> Option<Vec<f64>> {
    if base.len() != after.len() {
        return None;
    }
    let mut out = vec![0.0; rows.len()];
    for (b, a) in base.iter().zip(after) {
        if a.0 != b.0 {
            return None;
        }
        if let Some(&k) = at.get(&b.0) {
            if rows[k].sigma > 0.0 {
                out[k] = (a.1 - b.1) / PROBE_K / rows[k].sigma;
            }
        }
    }
    Some(out)
}

/// The campaign with column `c` moved by `PROBE_K` times `phi` (per pose).
fn probed(campaign: &Campaign, c: usize, phi: &[f64]) -> Campaign {
    let mut moved = campaign.clone();
    for (p, v) in moved.poses.iter_mut().zip(phi) {
        if let Some(Some(x)) = p.covariates.get_mut(c) {
            *x += PROBE_K * v;
        }
    }
    moved
}

/// The smooth terms in time of column `c`'s error ([`memory::smooth_terms`] at its rate's
/// window); None where the column has no rate (too few times, a reading missing).
fn basis(campaign: &Campaign, c: usize) -> Option<Vec<Vec<f64>>> {
    let t: Vec<f64> = campaign.poses.iter().map(|p| p.t).collect();
    let x: Vec<f64> = campaign
        .poses
        .iter()
        .map(|p| p.covariates.get(c).copied().flatten())
        .collect::<Option<_>>()?;
    let line = memory::Timeline::new(&t).ok()?;
    memory::smooth_terms(&t, memory::rate_window(&line, &x))
}

/// `rows` less their least-squares fit (in each row's noise) by `terms`, and the share of
/// χ² it took.
fn project_out(rows: &[RowValue], terms: &[Vec<f64>]) -> Option<(Vec<RowValue>, f64)> {
    if terms.is_empty() {
        return None;
    }
    let y: Vec<f64> = rows
        .iter()
        .map(|r| {
            if r.sigma > 0.0 {
                r.value / r.sigma
            } else {
                0.0
            }
        })
        .collect();
    let a = nalgebra::DMatrix::from_fn(rows.len(), terms.len(), |i, k| terms[k][i]);
    let b = nalgebra::DVector::from_vec(y.clone());
    let coef = a.clone().svd(true, true).solve(&b, 1e-12).ok()?;
    let fit = a * coef;
    let chi2: f64 = y.iter().map(|v| v * v).sum();
    let left: Vec<RowValue> = rows
        .iter()
        .zip(fit.iter())
        .map(|(r, f)| RowValue {
            value: r.value - f * r.sigma,
            ..r.clone()
        })
        .collect();
    let after: f64 = y.iter().zip(fit.iter()).map(|(v, f)| (v - f).powi(2)).sum();
    Some((left, if chi2 > 0.0 { 1.0 - after / chi2 } else { 0.0 }))
}
