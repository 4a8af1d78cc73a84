//! How noisy the instruments really were: variance-component estimation from a campaign's
//! own residuals (Förstner's iterated estimator, the multi-component form of Helmert's).
//!
//! Every row's variance is a sum over noise groups, Σ_i = Σ_k v_ik ([`crate::noise::Parts`]).
//! With r the residuals and h the leverages of the fit (diagonal of the hat matrix), each
//! group's variance factor is
//!
//! ```text
//!     f_k = [Σ_i v_ik r_i² / Σ_i²] / [Σ_i v_ik (1 − h_i) / Σ_i]
//! ```
//!
//! (its expected value is 1 when the assumed levels are right); the denominator is the
//! group's share of the redundancy, its degrees of freedom. The levels are scaled by √f_k,
//! the model re-fitted, until the factors settle. A group with too few degrees of freedom
//! keeps its assumed level and says so.

use crate::calib::{self, Calibration, CalibrationError, Options};
use crate::campaign::{Campaign, Instrument};
use crate::effects::EffectSet;
use crate::geometry;
use crate::noise::{Group, NoiseModel, N_GROUPS};
use crate::obs::RowValue;
use crate::params::{Model, Params};
use nalgebra::Vector2;

/// Fewest degrees of freedom for which a group's level is estimated.
pub const MIN_DOF: f64 = 5.0;
/// Re-fits at most; the factors usually settle in three.
const MAX_ROUNDS: usize = 8;
/// A round whose factors all lie within this of 1 ends the iteration.
const SETTLED: f64 = 0.01;
/// Bounds of an estimated level relative to the stated one: a noiseless (simulated) campaign
/// would otherwise drive the weights to infinity.
const FACTOR_RANGE: (f64, f64) = (1e-2, 1e2);

/// One group's level, as assumed and as estimated.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GroupNoise {
    pub group: &'static str,
    /// `um`, or `urad` for psi.
    pub unit: &'static str,
    /// The stated level (the spec's default, or `--noise`), per coordinate.
    pub assumed: f64,
    /// The level the campaign shows; equal to `assumed` when it could not be estimated.
    pub estimated: f64,
    /// Degrees of freedom of the estimate (the group's share of the redundancy).
    pub dof: f64,
    pub estimated_from_data: bool,
}

/// The noise a campaign shows.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseEstimate {
    /// The assumed model with the estimated levels: the weights of the final fit.
    pub model: NoiseModel,
    /// Only the groups the campaign has rows of.
    pub groups: Vec<GroupNoise>,
    pub rounds: usize,
}

impl NoiseEstimate {
    /// The assumed model, taken as it is (no estimation).
    pub fn assumed(model: &NoiseModel) -> NoiseEstimate {
        NoiseEstimate {
            model: model.clone(),
            groups: Vec::new(),
            rounds: 0,
        }
    }
}

/// Per group: (numerator, degrees of freedom) of the variance factor of the fit `rows` with
/// leverages `leverage`.
pub fn factor_terms(rows: &[RowValue], leverage: &[f64]) -> [(f64, f64); N_GROUPS] {
    let mut acc = [(0.0, 0.0); N_GROUPS];
    for (r, &h) in rows.iter().zip(leverage) {
        let var = r.sigma * r.sigma;
        if !(var > 0.0) {
            continue;
        }
        for (k, &v) in r.parts.iter().enumerate() {
            acc[k].0 += v * r.value * r.value / (var * var);
            acc[k].1 += v * (1.0 - h).max(0.0) / var;
        }
    }
    acc
}

/// Calibrate with the rows weighted by the noise the campaign itself shows: start from
/// `opts.noise` (the assumed levels), estimate each group's, re-weight, re-fit.
pub fn calibrate_estimating_noise(
    campaign: &Campaign,
    start: &Params,
    opts: &Options,
    effects: &EffectSet,
) -> Result<(Calibration, NoiseEstimate), CalibrationError> {
    calibrate_estimating_noise_after(campaign, start, opts, effects, None)
}

/// [`calibrate_estimating_noise`], its first round given: `first`, the same problem
/// calibrated from `start` with `opts.noise` (a caller that has made it, as the diagnosis's
/// first round, does not pay for it twice; it is not checked to be that calibration, so
/// the core's own callers only).
pub(crate) fn calibrate_estimating_noise_after(
    campaign: &Campaign,
    start: &Params,
    opts: &Options,
    effects: &EffectSet,
    mut first: Option<Calibration>,
) -> Result<(Calibration, NoiseEstimate), CalibrationError> {
    let assumed = opts.noise.clone();
    let mut o = opts.clone();
    let mut total = [1.0; N_GROUPS];
    let mut dof = [0.0; N_GROUPS];
    let mut rounds = 0;
    let mut last: Option<Calibration> = None;
    // the effects bound at the last round's parameters (`EffectSet::rebound`)
    let mut bound_at_fit: Option<EffectSet> = None;
    let mut rebinds = effects.rebinds();
    let cal = loop {
        let set = bound_at_fit.as_ref().unwrap_or(effects);
        // each round starts where the last ended: only the weights changed, so the LM takes
        // one or two steps instead of a calibration's four or five from the start
        let warm = last.as_ref().map(|c| calib::WarmStart {
            params: &c.params,
            theta: &c.theta,
            screen: false,
        });
        let cal = match first.take() {
            Some(cal) => cal,
            None => calib::calibrate_from(campaign, start, &o, set, &[], warm)?,
        };
        rounds += 1;
        let terms = factor_terms(&cal.residuals, &cal.leverage);
        let mut step = [1.0; N_GROUPS];
        for k in 0..N_GROUPS {
            dof[k] = terms[k].1;
            if terms[k].1 >= MIN_DOF && terms[k].0 > 0.0 {
                step[k] = (terms[k].0 / terms[k].1).sqrt().clamp(1e-2, 1e2);
            }
        }
        for k in 0..N_GROUPS {
            let bounded = (total[k] * step[k]).clamp(FACTOR_RANGE.0, FACTOR_RANGE.1);
            step[k] = bounded / total[k];
        }
        let settled = step.iter().all(|f| (f - 1.0).abs() < SETTLED);
        // a fit whose effects were bound at the start has a model error the next round,
        // bound at this fit, removes: settled weights alone do not end the rounds
        let bound_here = !rebinds || bound_at_fit.is_some();
        if (settled && bound_here) || rounds >= MAX_ROUNDS {
            break cal;
        }
        if rebinds {
            // an effect that bound at the start and not at the fit (a pose the fit moved to
            // a singular configuration) keeps its binding at the start
            bound_at_fit = effects.rebound(campaign, &cal.params).and_then(Result::ok);
            rebinds = bound_at_fit.is_some();
        }
        for k in 0..N_GROUPS {
            total[k] *= step[k];
        }
        o.noise = assumed.scaled(&total);
        last = Some(cal);
    };
    let distance = mean_tracker_distance(campaign, &assumed);
    let groups = Group::ALL
        .iter()
        .filter(|g| cal.residuals.iter().any(|r| r.parts[g.index()] > 0.0))
        .map(|&g| {
            let k = g.index();
            let (scale, unit) = g.report_unit();
            let from_data = dof[k] >= MIN_DOF;
            GroupNoise {
                group: g.name(),
                unit,
                assumed: assumed.sigma(g, distance) * scale,
                estimated: o.noise.sigma(g, distance) * scale,
                dof: dof[k],
                estimated_from_data: from_data,
            }
        })
        .collect();
    Ok((
        cal,
        NoiseEstimate {
            model: o.noise,
            groups,
            rounds,
        },
    ))
}

/// Mean distance (mm) from the tracker to the campaign's laser-tracker poses (nominal
/// model), where the across-beam level is reported; 0 without such poses.
fn mean_tracker_distance(campaign: &Campaign, noise: &NoiseModel) -> f64 {
    let nominal = Params::nominal();
    let d: Vec<f64> = campaign
        .poses
        .iter()
        .filter(|p| p.instrument == Instrument::Lt)
        .filter_map(|p| geometry::fgm(&nominal, Model::M29, p.q[0], p.q[3]).ok())
        .map(|s| noise.tracker_distance(Vector2::new(s.x(), s.y())))
        .collect();
    if d.is_empty() {
        0.0
    } else {
        d.iter().sum::<f64>() / d.len() as f64
    }
}
