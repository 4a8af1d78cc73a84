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
//! keeps its assumed level and says so. The rounds themselves are the calibration's
//! ([`crate::calib::Noise::Estimate`]); this module is their arithmetic.

use crate::campaign::{Campaign, Instrument};
use crate::geometry;
use crate::noise::{Group, NoiseModel, N_GROUPS};
use crate::obs::RowValue;
use crate::params::{Model, Params};
use nalgebra::Vector2;

/// Fewest degrees of freedom for which a group's level is estimated.
pub const MIN_DOF: f64 = 5.0;
/// Re-fits at most; the factors usually settle in three.
pub const MAX_ROUNDS: usize = 8;
/// A round whose factors all lie within this of 1 ends the iteration.
const SETTLED: f64 = 0.01;
/// Bounds of an estimated level relative to the stated one: a noiseless (simulated) campaign
/// would otherwise drive the weights to infinity. A level at a bound is a cap, not an
/// estimate ([`GroupNoise::capped`]).
pub const FACTOR_RANGE: (f64, f64) = (1e-2, 1e2);

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
    /// Whether the estimate stopped at a bound of [`FACTOR_RANGE`] (100x or 0.01x the stated
    /// level): the residuals asked for more (or less), so `estimated` is the cap the
    /// estimation allows, not what the campaign shows.
    pub capped: bool,
    /// Whether `assumed` is the default rating, [`NoiseModel::default`]'s (the spec's figure,
    /// or rpkm's own where the spec gives none), rather than one stated with `--noise`.
    pub default_rating: bool,
}

/// The noise a campaign shows.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseEstimate {
    /// The assumed model with the estimated levels: the weights of the final fit.
    pub model: NoiseModel,
    /// Only the groups the campaign has rows of.
    pub groups: Vec<GroupNoise>,
    pub rounds: usize,
    /// How many times `model` exceeds the stated noise at most (at least 1): the
    /// [`crate::calib::Options::noise_inflation`] of a calibration weighted by it.
    pub inflation: f64,
}

impl NoiseEstimate {
    /// The assumed model, taken as it is (no estimation).
    pub fn assumed(model: &NoiseModel) -> NoiseEstimate {
        NoiseEstimate {
            model: model.clone(),
            groups: Vec::new(),
            rounds: 0,
            inflation: 1.0,
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

/// The rounds' running state: each group's level as a factor of its stated one, and the
/// degrees of freedom of its last estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupLevels {
    pub total: [f64; N_GROUPS],
    pub dof: [f64; N_GROUPS],
}

impl Default for GroupLevels {
    fn default() -> Self {
        GroupLevels {
            total: [1.0; N_GROUPS],
            dof: [0.0; N_GROUPS],
        }
    }
}

impl GroupLevels {
    /// One round's re-weighting from the fit's `rows` and `leverage`: each group's step
    /// factor (1 where the group has too few degrees of freedom), kept inside
    /// [`FACTOR_RANGE`] of the stated level. Returns the steps; [`GroupLevels::apply`] takes them.
    pub fn step(&mut self, rows: &[RowValue], leverage: &[f64]) -> [f64; N_GROUPS] {
        let terms = factor_terms(rows, leverage);
        std::array::from_fn(|k| {
            let (num, dof) = terms[k];
            self.dof[k] = dof;
            let step = if dof >= MIN_DOF && num > 0.0 {
                (num / dof).sqrt().clamp(1e-2, 1e2)
            } else {
                1.0
            };
            (self.total[k] * step).clamp(FACTOR_RANGE.0, FACTOR_RANGE.1) / self.total[k]
        })
    }

    /// Whether every step lies within [`SETTLED`] of 1.
    pub fn settled(step: &[f64; N_GROUPS]) -> bool {
        step.iter().all(|f| (f - 1.0).abs() < SETTLED)
    }

    /// Take the steps: the levels the next round weights by.
    pub fn apply(&mut self, step: &[f64; N_GROUPS], stated: &NoiseModel) -> NoiseModel {
        for (t, s) in self.total.iter_mut().zip(step) {
            *t *= s;
        }
        stated.scaled(&self.total)
    }

    /// How many times the levels exceed the stated noise at most (at least 1).
    pub fn inflation(&self) -> f64 {
        self.total.iter().copied().fold(1.0, f64::max)
    }

    /// The estimate to report: `stated` against `weighted` (the levels of the last round)
    /// for every group the campaign's `rows` have.
    pub fn estimate(
        &self,
        campaign: &Campaign,
        stated: &NoiseModel,
        weighted: NoiseModel,
        rows: &[RowValue],
        rounds: usize,
    ) -> NoiseEstimate {
        let distance = mean_tracker_distance(campaign, stated);
        let default = NoiseModel::default();
        let groups = Group::ALL
            .iter()
            .filter(|g| rows.iter().any(|r| r.parts[g.index()] > 0.0))
            .map(|&g| {
                let k = g.index();
                let (scale, unit) = g.report_unit();
                GroupNoise {
                    group: g.name(),
                    unit,
                    assumed: stated.sigma(g, distance) * scale,
                    estimated: weighted.sigma(g, distance) * scale,
                    dof: self.dof[k],
                    estimated_from_data: self.dof[k] >= MIN_DOF,
                    capped: self.dof[k] >= MIN_DOF && at_bound(self.total[k]),
                    default_rating: {
                        let (a, b) = (stated.sigma(g, distance), default.sigma(g, distance));
                        (a - b).abs() <= 1e-9 * b.abs()
                    },
                }
            })
            .collect();
        NoiseEstimate {
            model: weighted,
            groups,
            rounds,
            inflation: self.inflation(),
        }
    }
}

/// Whether a level's factor of its stated one lies at a bound of [`FACTOR_RANGE`] (to the
/// rounding of the rounds' products).
fn at_bound(factor: f64) -> bool {
    factor >= FACTOR_RANGE.1 * (1.0 - 1e-9) || factor <= FACTOR_RANGE.0 * (1.0 + 1e-9)
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
