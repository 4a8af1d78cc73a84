//! Model discovery: where the model fails, which physical effect is missing, and what the
//! held-out error becomes once it is added. No step hinges on an assumed noise level.
//!
//! 1. Calibrate the current model (geometry under its manufacturing-tolerance prior + the
//!    effects already in it) with the rows weighted by the noise the campaign itself shows:
//!    each group's level (tracker along and across the beam, grid encoder, ball-bar,
//!    interferometer, angle optics, encoders) is estimated from the residuals
//!    ([`crate::variance`]) and reported next to the assumed one.
//! 2. For each effect of the library not in the model: bind it (it may not apply: no
//!    temperature column, no drive forces), calibrate with it (same weights), and compare with
//!    the nested F-test F = (Δχ²/k) / (χ²₁/ν₁) (k: the parameters it adds, ν: rows less the
//!    effective parameters), at level α/m (Bonferroni over the m candidates); the ratio is free
//!    of the noise's absolute level. An effect of several physical parts (thermal: rods,
//!    frame, scales) keeps only the parts the data support (|estimate| ≥ 2σ); the test is made
//!    on the whole family so that this choice does not bias it.
//! 3. The residual is also tested against a dictionary of smooth structure (covariates,
//!    derived covariates such as the direction of the last move, drive forces, time,
//!    workspace polynomials; [`sparse`]), each term in each instrument direction.
//! 4. The verdict: the best candidate by the Bayesian information criterion's gain
//!    Δχ² − k ln n that is significant and explains more than the best single dictionary term
//!    does (an effect that is right explains the residual in every direction at once; one
//!    that only borrows part of another signature does not) is the missing effect; otherwise
//!    a significant dictionary term is unexplained structure; otherwise nothing is missing,
//!    even when the instruments are noisier than rated (the noise table says so).

pub mod cross;
pub mod neighbours;
pub mod periodic;
pub mod sparse;

use crate::calib::{
    self, Calibration, CalibrationError, EffectEstimate, Prior, Request, SharedRows,
};
use crate::campaign::{Campaign, Instrument};
use crate::effects::{self, Effect, EffectSet, NotApplicable};
use crate::geometry;
use crate::noise::{Group, NoiseModel, XyInstrument, N_GROUPS};
use crate::obs::{self, PoseError, RowValue};
use crate::params::{Model, Params};
use crate::stats;
use crate::variance::{GroupNoise, NoiseEstimate};
use nalgebra::{DMatrix, DVector, Vector2};
use std::collections::BTreeMap;

/// Fraction of an effect parameter's plausible magnitude below which a significant estimate
/// is no missing physics: a model's approximation seen at encoder precision (a bow of
/// 0.1 µm) is significant on a thousand rows, and irrelevant.
pub const RELEVANT_FRACTION: f64 = 0.05;

/// RMS (mm) of the length residuals below which the data are taken as noise-free (simulated):
/// what structure remains is the solvers' round-off, not physics.
pub const NUMERICAL_RMS_MM: f64 = 1e-6;

/// Options of a diagnosis.
#[derive(Clone, Debug)]
pub struct Options {
    /// The geometric model (24: rod 5 linked to rod 4).
    pub model: Model,
    /// Significance level of the tests (family-wise over the candidates).
    pub alpha: f64,
    /// The instruments' stated noise: the start of the estimation, and the rating the
    /// estimates are compared with.
    pub noise: NoiseModel,
    /// How the rows are weighted once the strongest candidate is known: by each noise
    /// group's level estimated from the campaign (default), or by the stated levels.
    pub weighting: calib::Noise,
    /// Manufacturing tolerances of the geometric parameters.
    pub prior: Prior,
    /// Threads the candidate effects are fitted on (0: every core). The result does not
    /// depend on it.
    pub threads: usize,
    /// Screen the candidates (default): each first takes one Gauss-Newton step from the
    /// current model's minimum, and only one that may be significant then (p below
    /// [`SCREEN_P`]) is fitted to convergence. False: every candidate is fitted to
    /// convergence (the same verdicts, several times the time; for comparison).
    pub screen: bool,
    /// Set from another thread to stop the diagnosis: its fits stop at their next LM
    /// iteration and it returns [`DiagnoseError::Cancelled`].
    pub stop: Option<calib::Stop>,
}

impl Options {
    /// Whether the caller asked the diagnosis to stop ([`Options::stop`]).
    fn stopped(&self) -> bool {
        self.stop.as_ref().is_some_and(calib::Stop::requested)
    }
}

impl Default for Options {
    fn default() -> Self {
        Options {
            model: Model::M24,
            alpha: 0.001,
            noise: NoiseModel::default(),
            weighting: calib::Noise::ESTIMATE,
            prior: Prior::default(),
            threads: 0,
            screen: true,
            stop: None,
        }
    }
}

/// A diagnosis that could not be made.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("cancelled")]
    Cancelled,
    #[error("calibrating the current model: {0}")]
    Baseline(#[source] CalibrationError),
    #[error("effect in the model: {0}")]
    Effect(#[from] NotApplicable),
    #[error("held-out data: {0}")]
    Validation(#[source] PoseError),
    #[error("TCP error vectors: {0}")]
    Vectors(#[source] PoseError),
}

/// The fit of one model (the current one, or with a candidate effect).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Fit {
    /// χ² = Σ (r/σ)² of the calibration rows, its degrees of freedom (rows less the
    /// effective number of parameters) and χ²/ν.
    pub chi2: f64,
    pub dof: f64,
    pub chi2_per_dof: f64,
    /// RMS of the length rows of the calibration (µm).
    pub cal_rms_um: f64,
    /// RMS of the held-out TCP errors (µm), if there are held-out data.
    pub val_rms_um: Option<f64>,
    /// The held-out TCP errors (mm) less the mean of their setup and coordinate (the zero
    /// reading's error, which no model predicts), to compare two models pose by pose.
    #[serde(skip)]
    pub val_errors: Vec<f64>,
    /// Effect parameters identified.
    pub effect_params: Vec<EffectEstimate>,
    /// Parameter combinations the campaign determined better than their tolerance, of how
    /// many.
    pub determined: Option<(usize, usize)>,
    /// The identified geometric parameters.
    #[serde(skip)]
    pub params: Params,
    /// The effects' parameters (the calibration's θ).
    #[serde(skip)]
    pub theta: Vec<f64>,
}

/// The current model's fit and its test against the stated noise (the JSON's `baseline`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Baseline {
    pub cal_rms_um: f64,
    pub val_rms_um: Option<f64>,
    /// RMS that noise alone would give on the held-out errors (or, without held-out data, on
    /// the calibration's length rows), µm, at the estimated noise levels. It counts the
    /// reading each setup was zeroed on at its variance, but all the poses of a setup share
    /// that one draw: with few setups the held-out RMS strays from it by that draw.
    pub noise_floor_um: f64,
    /// The held-out RMS with each setup's zero removed (its errors less their mean, per
    /// coordinate: what a model can predict), µm, and the RMS noise alone would give there:
    /// the zero reading cancels, so they compare like with like whatever it drew.
    pub val_rms_relative_um: Option<f64>,
    pub noise_floor_relative_um: Option<f64>,
    /// χ² against the stated (not the estimated) noise, its dof and p-value: how the
    /// residual compares with the instruments' rating. Not used by the verdict.
    pub chi2: f64,
    pub dof: f64,
    pub chi2_per_dof: f64,
    /// P(χ²_ν ≥ χ²): small when the residual is more than the rated noise.
    pub p_value: f64,
    pub consistent_with_noise: bool,
    /// The held-out TCP errors (mm) less their setup's zero mean, as candidates are judged:
    /// to compare the models of successive diagnoses pose by pose ([`Prediction::of`]).
    #[serde(skip)]
    pub val_errors: Vec<f64>,
}

/// An effect tried as an addition to the model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    pub effect: String,
    pub significant: bool,
    /// Whether its size matters: some identified parameter reaches [`RELEVANT_FRACTION`] of
    /// the plausible magnitude the effect declares for it.
    pub relevant: bool,
    /// Fraction of the calibration's χ² above its degrees of freedom that the effect
    /// removes, 0..1.
    pub explained_fraction: f64,
    pub val_rms_before_um: Option<f64>,
    pub val_rms_after_um: Option<f64>,
    pub chi2_per_dof_after: f64,
    /// Nested F-test of the whole family: statistic, its degrees of freedom and p-value.
    pub f_statistic: f64,
    pub f_dof: (f64, f64),
    pub p_value: f64,
    /// Improvement of the Bayesian information criterion (Δχ² − k ln n) of the parts kept:
    /// the ranking.
    pub bic_gain: f64,
    /// The effect's parameters as identified (parts the data do not support held at 0,
    /// `identified` false).
    pub params: Vec<EffectEstimate>,
    /// χ²/dof of the current model (at the estimated noise), before the effect.
    pub chi2_per_dof_before: f64,
    /// The covariate of the effect the current model's residual follows most, if the effect
    /// has covariates: the evidence an engineer can check in the data.
    pub follows: Option<sparse::Pointer>,
    /// Whether the model predicts better with it: held-out errors compared pose by pose
    /// (None without held-out data).
    pub prediction: Option<Prediction>,
    /// The same judged by cross-validation by setup on the calibration campaign, where the
    /// held-out data cannot tell (none, or a change within its standard error: an effect the
    /// held-out instrument does not see, forces, or setup-local parameters), for a candidate
    /// that could be named.
    pub cross_validated: Option<Prediction>,
    /// Where neither it nor another significant candidate predicts better alone: the held-out
    /// comparison of the model with both (two effects hidden together each absorb part of the
    /// other alone), and the other's name.
    pub together: Option<(String, Prediction)>,
}

impl Candidate {
    /// How the candidate alone predicts: the held-out comparison where it decides (better,
    /// or clearly worse), else cross-validation by setup.
    pub fn alone(&self) -> Option<Prediction> {
        self.prediction
            .filter(|p| p.better || p.worse)
            .or(self.cross_validated)
    }
}

/// Does a candidate make the model predict better? Its held-out RMS against the current
/// model's, on the same poses: an effect that fits the campaign and predicts worse absorbs
/// something else, and is never named.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Prediction {
    /// RMS of the errors before and after, in `unit`.
    pub rms_before: f64,
    pub rms_after: f64,
    /// Standard error of the fall, from the paired squared errors.
    pub standard_error: f64,
    /// `um` (held-out TCP errors) or `sigma` (left-out rows of every instrument, each in its
    /// own noise).
    pub unit: &'static str,
    /// The RMS fell by more than its standard error.
    pub better: bool,
    /// The RMS rose by more than twice its standard error: clearly worse (a rise within
    /// that is a tie, which the held-out data do not decide: an effect they do not see
    /// would otherwise be refused one time in six by chance).
    pub worse: bool,
    /// Judged by cross-validation by setup on the calibration campaign.
    pub by_setup: bool,
}

impl Prediction {
    /// The comparison of the held-out TCP errors `before` and `after` (mm, the same poses in
    /// the same order); None without poses.
    pub fn of(before: &[f64], after: &[f64]) -> Option<Prediction> {
        Self::compared(before, after).map(|p| Prediction {
            rms_before: p.rms_before * 1e3,
            rms_after: p.rms_after * 1e3,
            standard_error: p.standard_error * 1e3,
            unit: "um",
            ..p
        })
    }

    /// The comparison of errors in any one unit (left-out rows in σ: `unit` sigma).
    fn compared(before: &[f64], after: &[f64]) -> Option<Prediction> {
        let n = before.len();
        if n < 2 || after.len() != n {
            return None;
        }
        let d: Vec<f64> = before
            .iter()
            .zip(after)
            .map(|(b, a)| b * b - a * a)
            .collect();
        let mean = d.iter().sum::<f64>() / n as f64;
        let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        let (rb, ra) = (calib::rms(before), calib::rms(after));
        // the RMS's fall and its error through d(RMS²) = (RMS_b + RMS_a) d(RMS)
        let se = (var / n as f64).sqrt() / (rb + ra).max(f64::MIN_POSITIVE);
        Some(Prediction {
            rms_before: rb,
            rms_after: ra,
            standard_error: se,
            unit: "sigma",
            better: rb - ra > se,
            worse: ra - rb > 2.0 * se,
            by_setup: false,
        })
    }
}

/// An effect that could not be tried, and why.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Skipped {
    pub effect: String,
    pub reason: String,
}

/// RMS of one instrument direction against its (estimated) noise.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GroupRms {
    pub instrument: String,
    pub direction: String,
    pub rows: usize,
    /// µm (µrad for ψ, N for a drive force).
    pub rms: f64,
    pub noise: f64,
    pub chi2_per_row: f64,
}

/// One calibration residual, located for plots (heat maps over the workspace, against time
/// and covariates).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Point {
    pub pose: usize,
    pub line: usize,
    pub instrument: String,
    pub direction: String,
    /// TCP of the pose (nominal forward model of q1, q4), mm.
    pub x: f64,
    pub y: f64,
    pub t: f64,
    /// Residual and its σ: µm (µrad for ψ, N for a drive force).
    pub value: f64,
    pub sigma: f64,
}

/// What the diagnosis concludes (the JSON's `verdict_kind`; other tools rely on the names).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VerdictKind {
    NothingMissing,
    MissingEffect,
    UnexplainedStructure,
}

/// One noise group in the JSON's `noise` map.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NoiseReport {
    pub unit: &'static str,
    pub assumed: f64,
    pub estimated: f64,
    pub dof: f64,
}

/// The diagnosis (serialises to the JSON other tools read: `verdict_kind`, `missing_effect`,
/// `noise`, `baseline`, `candidates`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Diagnosis {
    pub model: String,
    pub effects_in_model: Vec<String>,
    pub verdict_kind: VerdictKind,
    pub missing_effect: Option<String>,
    /// χ²/dof of the current model at the estimated noise (near 1 when nothing is missing).
    pub chi2_per_dof: f64,
    /// The current model's calibrated geometric parameters (mm, rad) by name: the
    /// calibration the verdict rests on, the one `rpkm calibrate` makes with the same options.
    pub parameters: BTreeMap<String, f64>,
    /// Per group: the stated and the estimated noise.
    pub noise: BTreeMap<String, NoiseReport>,
    /// The candidates that joined the current model for the noise estimate (round 1's
    /// significant ones): a model that misses an effect would count it as noise.
    pub noise_estimated_with: Vec<String>,
    /// The same, with whether each was estimated from the data.
    #[serde(skip)]
    pub noise_groups: Vec<GroupNoise>,
    /// Parameter combinations the campaign determined better than their tolerance, of how
    /// many (the rest stayed at the prior).
    pub determined: Option<(usize, usize)>,
    pub baseline: Baseline,
    pub candidates: Vec<Candidate>,
    pub skipped: Vec<Skipped>,
    /// The dictionary test of the current model's residual.
    pub structure: sparse::Structure,
    /// The strongest period of the current model's residual in a carrier's position.
    pub periodic: Option<periodic::Periodic>,
    /// The direction whose residuals are most alike along the setups' paths.
    pub neighbours: Option<neighbours::Neighbours>,
    /// The dictionary term that explained the residual as well as the named effect: the
    /// effect was preferred because it predicts held-out data, which a term cannot.
    pub tied_term: Option<String>,
    /// The second missing effect, where the named one predicts better only together with
    /// it (alone, each absorbs part of the other): add both.
    pub together_with: Option<String>,
    /// Noise groups estimated more than [`NOISIER_THAN_RATED`] times their rating: either
    /// the instrument is that noisy or something is missing that the tests cannot see.
    pub noisier_than_rated: Vec<Noisier>,
    /// What the residual left by the verdict's model follows, when it is still structured.
    pub unexplained: Option<sparse::Pointer>,
    pub groups: Vec<GroupRms>,
    /// Residuals of the current model, worst (largest |r/σ|) first.
    pub points: Vec<Point>,
    /// The current model's TCP error of every tracker and grid-encoder pose as a vector, from
    /// the same fit as `points`.
    pub error_vectors: Vec<ErrorVector>,
    /// Why `error_vectors` is empty although the campaign has such poses, if it is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_vectors_missing: Option<String>,
    /// How the verdict was tested.
    pub test: Test,
}

/// How a diagnosis tested its verdict.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Test {
    /// Rounds of the noise estimation per group.
    pub noise_rounds: usize,
    /// Level of each candidate's nested F-test (Bonferroni over the candidates tried).
    pub candidate_level: f64,
    pub candidates_tried: usize,
    /// Level of the dictionary test of the residual.
    pub dictionary_level: f64,
    /// Rows of the calibration.
    pub rows: usize,
}

/// What one fit produced: its final rows and statistics.
struct Fitted {
    rows: Vec<RowValue>,
    fit: Fit,
}

/// Held-out data with their noise.
struct Validation<'a> {
    campaign: &'a Campaign,
    /// σ of each held-out TCP error, in [`obs::tcp_errors`] order.
    sigma: Vec<f64>,
    /// σ of each error less the mean of its setup and coordinate ([`Validation::relative`]):
    /// the zero reading cancels, the mean's own noise does not.
    relative_sigma: Vec<f64>,
    /// Each error's setup and coordinate (an index): the errors of one share the reading
    /// their setup was zeroed on.
    zero: Vec<usize>,
}

impl Validation<'_> {
    /// The held-out campaign with the noise of each of its TCP errors.
    fn new<'a>(campaign: &'a Campaign, noise: &NoiseModel) -> Result<Validation<'a>, PoseError> {
        let errs = obs::tcp_errors(campaign, &Params::nominal(), Model::M29)?;
        let variances = validation_variances(campaign, &errs, noise)?;
        let zero = zero_groups(campaign, &errs);
        let reading: Vec<f64> = variances.iter().map(|v| v.reading).collect();
        // var(e_i − ē) = σ_i² (1 − 2/n) + Σ σ_j² / n² over the n errors of the group
        let sum = group_sums(&zero, &reading);
        let relative_sigma = zero
            .iter()
            .zip(&reading)
            .map(|(&g, v)| {
                let n = sum[g].1.max(1) as f64;
                (v * (1.0 - 2.0 / n) + sum[g].0 / (n * n)).max(0.0).sqrt()
            })
            .collect();
        Ok(Validation {
            campaign,
            sigma: variances
                .iter()
                .map(|v| (v.reading + v.zero).sqrt())
                .collect(),
            relative_sigma,
            zero,
        })
    }

    /// `errors` less the mean of their setup and coordinate: what a model can predict of
    /// them (no model predicts the error of the reading a setup was zeroed on, and one that
    /// happens to follow it would beat the truth).
    fn relative(&self, errors: &[f64]) -> Vec<f64> {
        let sum = group_sums(&self.zero, errors);
        self.zero
            .iter()
            .zip(errors)
            .map(|(&g, e)| e - sum[g].0 / sum[g].1.max(1) as f64)
            .collect()
    }
}

/// Per group of `zero` (an index per value), the sum of `values` and their count.
fn group_sums(zero: &[usize], values: &[f64]) -> Vec<(f64, usize)> {
    let n = zero.iter().max().map_or(0, |m| m + 1);
    let mut sum = vec![(0.0, 0usize); n];
    for (&g, v) in zero.iter().zip(values) {
        sum[g].0 += v;
        sum[g].1 += 1;
    }
    sum
}

/// Each held-out TCP error's (setup, coordinate) as an index, in [`obs::tcp_errors`] order.
fn zero_groups(val: &Campaign, errs: &[(usize, &'static str, f64)]) -> Vec<usize> {
    let mut keys: Vec<(&str, &str)> = Vec::new();
    errs.iter()
        .map(|(i, coordinate, _)| {
            let key = (val.poses[*i].setup.as_str(), *coordinate);
            keys.iter().position(|k| *k == key).unwrap_or_else(|| {
                keys.push(key);
                keys.len() - 1
            })
        })
        .collect()
}

/// Diagnose `campaign` with `in_model` effects already in the model; `validation` is held out.
pub fn diagnose(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    in_model: &[&dyn Effect],
    opts: &Options,
) -> Result<Diagnosis, DiagnoseError> {
    diagnose_among(campaign, validation, in_model, &[], opts)
}

/// [`diagnose`], with the effects `offered` (written ones, `effects::Written`) tried as
/// candidates beside the library's: the same tests, at the same level for each.
pub fn diagnose_among(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    in_model: &[&dyn Effect],
    offered: &[&dyn Effect],
    opts: &Options,
) -> Result<Diagnosis, DiagnoseError> {
    let diagnosis = rounds(campaign, validation, in_model, offered, opts);
    // a fit stopped part-way fails as it can (a candidate not fitted, a round's error):
    // whatever came of it, a stopped diagnosis concludes nothing
    if opts.stopped() {
        return Err(DiagnoseError::Cancelled);
    }
    diagnosis
}

/// The two rounds of [`diagnose_among`].
fn rounds(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    in_model: &[&dyn Effect],
    offered: &[&dyn Effect],
    opts: &Options,
) -> Result<Diagnosis, DiagnoseError> {
    let library = effects::library();
    let in_names: Vec<&str> = in_model.iter().map(|e| e.name()).collect();
    let tried: Vec<&dyn Effect> = library
        .iter()
        .map(std::convert::AsRef::as_ref)
        .chain(offered.iter().copied())
        .filter(|e| !in_names.contains(&e.name()))
        .filter(|e| !(e.name() == "parallelogram" && opts.model == Model::M29))
        .collect();
    let search = Search {
        campaign,
        validation,
        in_model,
        tried: &tried,
        level: opts.alpha / tried.len().max(1) as f64,
        threads: opts.threads,
        screen: opts.screen,
    };
    // Round 1, rows weighted by the stated noise: which effect, if any, stands out. (Under
    // noise estimated with the current model, its misfit inflates the levels and dims the
    // very effect that would explain it.)
    let stated = calib_options(opts);
    let (base1, first, cal1) = search.round(&stated, None)?;
    if opts.stopped() {
        return Err(DiagnoseError::Cancelled);
    }
    // noise-free (simulated) data: no noise to estimate, the stated weights stay
    if calib::rms(&length_values(&base1.rows)) < NUMERICAL_RMS_MM {
        let est = NoiseEstimate::assumed(&opts.noise);
        let val = held_out(validation, &opts.noise)?;
        let baseline = baseline(&base1, &opts.noise, val.as_ref(), opts);
        return Ok(conclude(&search, opts, &base1, baseline, first, &est));
    }
    // Round 2: the noise estimated under the model with every significant candidate (or the
    // current model), and every model compared again with those weights (the nested tests
    // need one weighting, any fixed one). A model that misses an effect puts it in the
    // noise (a 100x encoder "noise" under a model without thermal), and the next step of
    // the loop, weighted otherwise, would judge another problem; a few parameters too many
    // cost the estimate a few of its hundreds of degrees of freedom.
    let under = noise_model(in_model, &first.candidates, &tried, Candidates::Significant);
    // under the current model itself the noise estimation's first round is round 1's base
    let same = under.len() == in_model.len();
    let first_fit = cal1.as_ref().filter(|_| same);
    let (cal, est, copts, under) = match current_model(campaign, &under, opts, first_fit) {
        Ok((cal, est, copts)) => (cal, est, copts, under),
        // the significant candidates together cannot be fitted (one absorbs another to a
        // singular step): the strongest alone, as the loop did before it took them all
        Err(_) if under.len() > in_model.len() + 1 => {
            let under = noise_model(in_model, &first.candidates, &tried, Candidates::Strongest);
            let (cal, est, copts) = current_model(campaign, &under, opts, None)?;
            (cal, est, copts, under)
        }
        Err(e) => return Err(e),
    };
    // the noise was estimated under the current model itself: its last fit is the base
    let fitted = same.then_some(cal);
    let (base, round, _) = search.round(&copts, fitted)?;
    let val = held_out(validation, &est.model)?;
    let baseline = baseline(&base, &est.model, val.as_ref(), opts);
    let mut diagnosis = conclude(&search, opts, &base, baseline, round, &est);
    diagnosis.noise_estimated_with = under[in_model.len()..]
        .iter()
        .map(|e| e.name().to_owned())
        .collect();
    Ok(diagnosis)
}

/// What every round of a diagnosis shares.
struct Search<'a> {
    campaign: &'a Campaign,
    validation: Option<&'a Campaign>,
    in_model: &'a [&'a dyn Effect],
    tried: &'a [&'a dyn Effect],
    /// Level of each candidate's test (Bonferroni).
    level: f64,
    /// Threads the candidates are fitted on.
    threads: usize,
    /// Whether candidates are screened first ([`Options::screen`]).
    screen: bool,
}

impl Search<'_> {
    /// The current model and every candidate, calibrated with `copts` (its noise weights the
    /// rows and the held-out errors); the current model's calibration with `copts` when it
    /// is at hand (`fitted`), else made here and returned (the noise estimation's first
    /// round when the current model stays).
    fn round(
        &self,
        copts: &calib::Options,
        fitted: Option<Calibration>,
    ) -> Result<(Fitted, Round, Option<Calibration>), DiagnoseError> {
        let val = held_out(self.validation, &copts.noise)?;
        let (cal, made) = if let Some(cal) = fitted {
            (cal, None)
        } else {
            let cal = fit_model(self.campaign, self.in_model, copts)?;
            (cal.clone(), Some(cal))
        };
        // a picture, not a number the verdict rests on: a pose the forward model cannot
        // solve costs the arrows, not the diagnosis
        let vectors = error_vectors(self.campaign, self.in_model, &cal, copts.model)
            .map_err(|e| e.to_string());
        let base = finish(self.campaign, val.as_ref(), self.in_model, cal, copts)?;
        let tries = try_all(
            self.campaign,
            val.as_ref(),
            (self.in_model, &base.fit),
            self.tried,
            copts,
            (self.threads, self.screen),
        );
        let mut round = Round {
            vectors,
            ..candidates(self.campaign, self.tried, tries, &base, self.level)
        };
        self.cross_validate(&mut round, &base, copts);
        if let Some(val) = val.as_ref() {
            self.pair_up(&mut round, &base, copts, val);
        }
        Ok((base, round, made))
    }
}

/// Significant candidates tried in pairs where none predicts better alone: the best few by
/// BIC gain.
const PAIRED: usize = 3;

impl Search<'_> {
    /// Where no candidate that could be named predicts better alone, the best few are
    /// fitted in pairs: two effects hidden together each absorb part of the other when
    /// added alone, and predict worse; together they predict better. The first pair that
    /// does marks both ([`Candidate::together`]).
    fn pair_up(&self, round: &mut Round, base: &Fitted, copts: &calib::Options, val: &Validation) {
        let open = |c: &Candidate| c.significant && c.relevant;
        let alone = |c: &Candidate| c.alone().is_some_and(|p| p.better);
        if round.candidates.iter().filter(|c| open(c)).any(alone) {
            return;
        }
        let mut ranked: Vec<usize> = (0..round.candidates.len())
            .filter(|&k| open(&round.candidates[k]))
            .collect();
        ranked.sort_by(|&a, &b| {
            round.candidates[b]
                .bic_gain
                .total_cmp(&round.candidates[a].bic_gain)
        });
        ranked.truncate(PAIRED);
        for (n, &a) in ranked.iter().enumerate() {
            for &b in &ranked[n + 1..] {
                let names = [
                    round.candidates[a].effect.clone(),
                    round.candidates[b].effect.clone(),
                ];
                let Some(p) = self.pair(&names, base, copts, val) else {
                    continue;
                };
                if p.better {
                    round.candidates[a].together = Some((names[1].clone(), p));
                    round.candidates[b].together = Some((names[0].clone(), p));
                    return;
                }
            }
        }
    }

    /// The held-out comparison of the current model with the two effects `names` added
    /// (None where they cannot be fitted).
    fn pair(
        &self,
        names: &[String; 2],
        base: &Fitted,
        copts: &calib::Options,
        val: &Validation,
    ) -> Option<Prediction> {
        let mut with: Vec<&dyn Effect> = self.in_model.to_vec();
        for name in names {
            with.push(*self.tried.iter().find(|e| e.name() == name)?);
        }
        let start = Params::nominal();
        let set = EffectSet::bind(&with, self.campaign, &start).ok()?;
        let theta = warm_theta(&set, &base.fit);
        let (cal, _) = calib::calibrate(&Request {
            effects: &set,
            warm: Some(calib::WarmStart {
                params: &base.fit.params,
                theta: &theta,
                screen: false,
            }),
            ..Request::new(self.campaign, &start, copts)
        })
        .ok()?;
        let fit = finish_with(Some(val), &with, &set, cal, copts).ok()?;
        Prediction::of(&base.fit.val_errors, &fit.fit.val_errors)
    }

    /// Each candidate that could be named and that held-out data cannot judge (none, or a
    /// tie) is judged by cross-validation by setup ([`cross`]): the current model's and the
    /// candidate's predictions of the setups each fold left out, compared row by row.
    fn cross_validate(&self, round: &mut Round, base: &Fitted, copts: &calib::Options) {
        let mut before: Option<Option<Vec<f64>>> = None;
        let undecided = |c: &Candidate| c.prediction.is_none_or(|p| !p.better && !p.worse);
        let open = |c: &&mut Candidate| c.significant && c.relevant && undecided(c);
        for c in round.candidates.iter_mut().filter(open) {
            let Some(effect) = self.tried.iter().find(|e| e.name() == c.effect) else {
                continue;
            };
            let Some((_, fit)) = round.fits.iter().find(|(name, _)| *name == c.effect) else {
                continue;
            };
            let base_rows = before.get_or_insert_with(|| {
                cross::predicted_rows(
                    self.campaign,
                    &cross::Fitted {
                        effects: self.in_model,
                        params: &base.fit.params,
                        theta: &base.fit.theta,
                    },
                    copts,
                )
            });
            let with = with_effect(self.in_model, *effect);
            let after = cross::predicted_rows(
                self.campaign,
                &cross::Fitted {
                    effects: &with,
                    params: &fit.fit.params,
                    theta: &fit.fit.theta,
                },
                copts,
            );
            if let (Some(b), Some(a)) = (base_rows.as_ref(), after) {
                c.cross_validated = Prediction::compared(b, &a).map(|p| Prediction {
                    by_setup: true,
                    ..p
                });
            }
        }
    }
}

/// The verdict from the last round.
fn conclude(
    search: &Search,
    opts: &Options,
    base: &Fitted,
    baseline: Baseline,
    round: Round,
    est: &NoiseEstimate,
) -> Diagnosis {
    let campaign = search.campaign;
    let in_names: Vec<&str> = search.in_model.iter().map(|e| e.name()).collect();
    let structure = sparse::structure(campaign, &base.rows);
    let Round {
        mut candidates,
        fits,
        skipped,
        vectors,
    } = round;
    candidates.sort_by(|a, b| b.bic_gain.total_cmp(&a.bic_gain));
    // each of the three structure tests at a third of the level: the family's stays α
    let level = opts.alpha / 3.0;
    let chosen = choose(
        campaign,
        (&candidates, &fits),
        (&structure, base.rows.len()),
        level,
    );
    let missing_effect = chosen.as_ref().map(|c| c.effect.clone());
    let remaining: &Fitted = missing_effect
        .as_ref()
        .and_then(|m| fits.iter().find(|(name, _)| name == m))
        .map_or(base, |(_, fit)| fit);
    let left = sparse::structure(campaign, &remaining.rows);
    let unexplained = (left.p_value < level)
        .then(|| left.pointer.clone())
        .flatten();
    let exact = calib::rms(&length_values(&base.rows)) < NUMERICAL_RMS_MM;
    let shape = Shape::of(campaign, &base.rows, &structure, level);
    let verdict_kind = match (&chosen, shape.structured() && !exact) {
        (Some(_), _) => VerdictKind::MissingEffect,
        (None, true) => VerdictKind::UnexplainedStructure,
        (None, false) => VerdictKind::NothingMissing,
    };
    let unexplained = if exact { None } else { unexplained };
    let test = Test {
        noise_rounds: est.rounds,
        candidate_level: search.level,
        candidates_tried: search.tried.len(),
        dictionary_level: level,
        rows: base.rows.len(),
    };
    Diagnosis {
        model: format!("{}", opts.model),
        effects_in_model: in_names.iter().map(|s| (*s).to_owned()).collect(),
        verdict_kind,
        missing_effect,
        chi2_per_dof: base.fit.chi2_per_dof,
        parameters: crate::params::NAMES
            .iter()
            .enumerate()
            .map(|(i, n)| ((*n).to_owned(), base.fit.params[i]))
            .collect(),
        noise: noise_map(&est.groups),
        noise_estimated_with: Vec::new(),
        noise_groups: est.groups.clone(),
        determined: base.fit.determined,
        baseline,
        candidates,
        skipped,
        structure,
        periodic: shape.periodic,
        neighbours: shape.neighbours,
        together_with: chosen.as_ref().and_then(|c| c.together_with.clone()),
        tied_term: chosen.and_then(|c| c.tied_term),
        noisier_than_rated: noisier(&est.groups),
        unexplained,
        groups: groups(&base.rows),
        points: points(campaign, &base.rows),
        error_vectors_missing: vectors.as_ref().err().cloned(),
        error_vectors: vectors.unwrap_or_default(),
        test,
    }
}

/// A noise estimate this many times the stated level (the rating, or the spec's default) is
/// never taken silently.
pub const NOISIER_THAN_RATED: f64 = 2.0;

/// A noise group estimated well above its rating.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Noisier {
    pub group: String,
    /// Estimated over stated level.
    pub ratio: f64,
}

/// The groups estimated from the data above [`NOISIER_THAN_RATED`] times their rating.
fn noisier(groups: &[GroupNoise]) -> Vec<Noisier> {
    groups
        .iter()
        .filter(|g| g.estimated_from_data && g.assumed > 0.0)
        .map(|g| Noisier {
            group: g.group.to_owned(),
            ratio: g.estimated / g.assumed,
        })
        .filter(|n| n.ratio > NOISIER_THAN_RATED)
        .collect()
}

/// The three structure tests of a residual, none resting on the noise's level: the
/// dictionary of smooth terms, the periodogram of the carriers' positions, and neighbours
/// along the setups' paths.
struct Shape {
    dictionary_p: f64,
    periodic: Option<periodic::Periodic>,
    neighbours: Option<neighbours::Neighbours>,
    level: f64,
}

impl Shape {
    fn of(
        campaign: &Campaign,
        rows: &[RowValue],
        dictionary: &sparse::Structure,
        level: f64,
    ) -> Shape {
        Shape {
            dictionary_p: dictionary.p_value,
            periodic: periodic::periodogram(campaign, rows, level),
            neighbours: neighbours::neighbours(campaign, rows),
            level,
        }
    }

    /// Whether any of the three finds structure at its level.
    fn structured(&self) -> bool {
        self.dictionary_p < self.level
            || self
                .periodic
                .as_ref()
                .is_some_and(|p| p.p_value < self.level)
            || self
                .neighbours
                .as_ref()
                .is_some_and(|n| n.p_value < self.level)
    }
}

/// The effect a round names, if any: the best-ranked candidate that is significant,
/// relevant, predicts held-out (or left-out) data better where there are such data (gains in
/// BIC where there are none), and is not outdone by a single dictionary term. A term that explains as much as the effect
/// gives way to it when the effect predicts better and leaves no structure behind (a term
/// cannot predict a pose it has not seen; the effect can).
fn choose(
    campaign: &Campaign,
    (candidates, fits): (&[Candidate], &[(String, Fitted)]),
    (structure, n_rows): (&sparse::Structure, usize),
    level: f64,
) -> Option<Chosen> {
    // a single dictionary term's BIC gain: what an effect must beat to be the explanation
    let term_bic = structure.explained_chi2 - (n_rows as f64).ln();
    candidates.iter().find_map(|c| {
        // where held-out (or left-out) data judge, a better prediction is the evidence that
        // the effect's parameters are worth their number (setup-local ones, an instrument's
        // alignment in each mounting, cost BIC per setup); else the information criterion is
        let judged = match (c.alone(), &c.together) {
            (Some(p), _) if p.better => Some(p),
            (_, Some((_, p))) => Some(*p),
            (j, None) => j,
        };
        let worth = judged.map_or(c.bic_gain > 0.0, |p| p.better);
        if !(c.significant && c.relevant && worth) {
            return None;
        }
        if c.bic_gain > term_bic {
            return Some(Chosen {
                effect: c.effect.clone(),
                tied_term: None,
                together_with: partner(c),
            });
        }
        let proven = judged.is_some_and(|p| p.better);
        let fit = fits.iter().find(|(name, _)| *name == c.effect)?;
        let clean = sparse::structure(campaign, &fit.1.rows).p_value >= level;
        (proven && clean).then(|| Chosen {
            effect: c.effect.clone(),
            tied_term: structure.pointer.as_ref().map(|p| p.feature.clone()),
            together_with: partner(c),
        })
    })
}

/// The partner of a candidate that predicts better only together with it.
fn partner(c: &Candidate) -> Option<String> {
    let alone = c.alone().is_some_and(|p| p.better);
    c.together
        .as_ref()
        .filter(|_| !alone)
        .map(|(name, _)| name.clone())
}

/// The effect a round names, and the dictionary term it was preferred to.
struct Chosen {
    effect: String,
    tied_term: Option<String>,
    /// The effect it predicts better with (and without which it predicts worse).
    together_with: Option<String>,
}

/// What trying every candidate gave.
struct Round {
    /// Each tried effect compared with the current model.
    candidates: Vec<Candidate>,
    /// Each compared effect's fit (the whole family, as the loop adds it), by effect name.
    fits: Vec<(String, Fitted)>,
    /// The effects that could not be tried, and why.
    skipped: Vec<Skipped>,
    /// The current model's TCP error vectors (2-D relative instruments), or why there are
    /// none (a pose whose forward model has no solution).
    vectors: Result<Vec<ErrorVector>, String>,
}

impl Default for Round {
    fn default() -> Self {
        Round {
            candidates: Vec::new(),
            fits: Vec::new(),
            skipped: Vec::new(),
            vectors: Ok(Vec::new()),
        }
    }
}

/// A candidate effect's fits: the full effect and the parts of it kept.
type Tried = Result<(Fitted, Fitted), FitError>;

/// Each effect of `tried` added to the model and fitted, in `tried`'s order, on `threads`
/// threads (0: every core). Each fit is independent and lands at its own index: the result
/// does not depend on the number of threads, nor on which thread fitted which candidate.
fn try_all(
    campaign: &Campaign,
    val: Option<&Validation>,
    (in_model, base): (&[&dyn Effect], &Fit),
    tried: &[&dyn Effect],
    copts: &calib::Options,
    (threads, screen): (usize, bool),
) -> Vec<Tried> {
    let start = Params::nominal();
    // each candidate's model bound once, here: its size orders the work below
    let bound: Vec<Result<EffectSet, NotApplicable>> = tried
        .iter()
        .map(|e| EffectSet::bind(&with_effect(in_model, *e), campaign, &start))
        .collect();
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let threads = if threads == 0 { cores } else { threads }.clamp(1, tried.len().max(1));
    let trials = Trials {
        campaign,
        val,
        in_model,
        base,
        start,
        screen,
        shared: shared_rows(campaign, (in_model, base), tried, &bound, copts),
        copts: calib::Options {
            // the candidates share the cores: each fit's rows on one thread
            threads: if threads == 1 { copts.threads } else { 1 },
            ..copts.clone()
        },
    };
    let mut out: Vec<Option<Tried>> = (0..tried.len()).map(|_| None).collect();
    let mut queue: Vec<(usize, EffectSet)> = Vec::new();
    for (i, set) in bound.into_iter().enumerate() {
        match set {
            Ok(set) => queue.push((i, set)),
            Err(e) => out[i] = Some(Err(e.into())),
        }
    }
    // largest first (the setup-local parameters of an instrument's alignment cost more than
    // all the other candidates together on a campaign of many setups), each thread taking
    // the next one when it is free: the last to finish is a small one
    queue.sort_by_key(|(i, set)| (std::cmp::Reverse(set.n_params()), *i));
    let one = |i: usize, set: EffectSet| trials.try_effect(tried[i], set);
    for (i, fit) in run_queue(queue, threads, &one) {
        out[i] = Some(fit);
    }
    out.into_iter().flatten().collect()
}

/// The rows at the start and at the current model's minimum with the effect columns of
/// every candidate that binds (`bound`), evaluated once for all of them; None where they
/// cannot be evaluated (each candidate then evaluates its own rows and reports why that
/// failed).
fn shared_rows(
    campaign: &Campaign,
    (in_model, base): (&[&dyn Effect], &Fit),
    tried: &[&dyn Effect],
    bound: &[Result<EffectSet, NotApplicable>],
    copts: &calib::Options,
) -> Option<SharedRows> {
    let start = Params::nominal();
    let mut union: Vec<&dyn Effect> = in_model.to_vec();
    union.extend(
        tried
            .iter()
            .zip(bound)
            .filter(|(_, b)| b.is_ok())
            .map(|(e, _)| *e),
    );
    let set = EffectSet::bind(&union, campaign, &start).ok()?;
    let theta = warm_theta(&set, base);
    SharedRows::new(campaign, &start, copts, &set, (&base.params, &theta)).ok()
}

/// What every candidate of a round shares.
struct Trials<'a> {
    campaign: &'a Campaign,
    val: Option<&'a Validation<'a>>,
    in_model: &'a [&'a dyn Effect],
    /// The current model's fit: where each candidate starts, and what it is tested against.
    base: &'a Fit,
    start: Params,
    /// Whether candidates are screened first ([`Options::screen`]).
    screen: bool,
    copts: calib::Options,
    /// The rows at the start and at the current model's minimum ([`shared_rows`]).
    shared: Option<SharedRows>,
}

/// `in_model` and `effect`: a candidate's model.
fn with_effect<'a>(in_model: &[&'a dyn Effect], effect: &'a dyn Effect) -> Vec<&'a dyn Effect> {
    let mut with = in_model.to_vec();
    with.push(effect);
    with
}

/// `one` applied to every (index, set) of `queue`, in order, on `threads` threads that each
/// take the next entry when free; the results with their indexes, in no particular order.
fn run_queue<T: Send>(
    queue: Vec<(usize, EffectSet)>,
    threads: usize,
    one: &(impl Fn(usize, EffectSet) -> T + Sync),
) -> Vec<(usize, T)> {
    if threads <= 1 {
        return queue.into_iter().map(|(i, set)| (i, one(i, set))).collect();
    }
    let queue = std::sync::Mutex::new(queue.into_iter());
    // a poisoned lock is a panic in another worker, which the join below passes on
    let next = || queue.lock().ok().and_then(|mut q| q.next());
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                let next = &next;
                scope.spawn(move || {
                    std::iter::from_fn(next)
                        .map(|(i, set)| (i, one(i, set)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            // a panic in a fit is a bug: it goes on in this thread
            .flat_map(|w| w.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    })
}

/// Compare every tried effect's fit with `base`.
fn candidates(
    campaign: &Campaign,
    tried: &[&dyn Effect],
    tries: Vec<Tried>,
    base: &Fitted,
    level: f64,
) -> Round {
    let mut out = Round::default();
    for (effect, fit) in tried.iter().zip(tries) {
        let skip = |reason: String| Skipped {
            effect: effect.name().to_owned(),
            reason,
        };
        match fit {
            Ok((full, kept)) => match compare(base, &full, &kept, *effect, campaign, level) {
                Some(c) => {
                    out.candidates.push(c);
                    out.fits.push((effect.name().to_owned(), full));
                }
                None => out.skipped.push(skip(
                    "no parameter of it is observable with this campaign (the geometry \
                     absorbs its signature)"
                        .to_owned(),
                )),
            },
            Err(e) => out.skipped.push(skip(e.to_string())),
        }
    }
    out
}

/// The most significant candidate (smallest p-value below the level): under weights the
/// misfit inflated, its BIC gain may still look small.
/// Which of round 1's candidates join the current model for the noise estimate.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Candidates {
    /// Every significant one that could be named.
    Significant,
    /// The most significant alone.
    Strongest,
}

/// The model the noise is estimated under: the current model and round 1's candidates
/// `which`, most significant first.
fn noise_model<'a>(
    in_model: &[&'a dyn Effect],
    candidates: &[Candidate],
    tried: &[&'a dyn Effect],
    which: Candidates,
) -> Vec<&'a dyn Effect> {
    let mut open: Vec<&Candidate> = candidates
        .iter()
        .filter(|c| c.significant && c.relevant)
        .collect();
    open.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
    if which == Candidates::Strongest {
        open.truncate(1);
    }
    let added = open
        .iter()
        .filter_map(|c| tried.iter().find(|e| e.name() == c.effect).copied());
    in_model.iter().copied().chain(added).collect()
}

/// The current model (`in_model` effects) calibrated with `copts` as they are.
fn fit_model(
    campaign: &Campaign,
    in_model: &[&dyn Effect],
    copts: &calib::Options,
) -> Result<Calibration, DiagnoseError> {
    let start = Params::nominal();
    let set = EffectSet::bind(in_model, campaign, &start)?;
    calib::calibrate(&Request {
        effects: &set,
        ..Request::new(campaign, &start, copts)
    })
    .map(|(cal, _)| cal)
    .map_err(DiagnoseError::Baseline)
}

/// The current model calibrated with the estimated noise, the estimate, and the calibration
/// options every candidate then shares.
fn current_model(
    campaign: &Campaign,
    in_model: &[&dyn Effect],
    opts: &Options,
    first: Option<&Calibration>,
) -> Result<(Calibration, NoiseEstimate, calib::Options), DiagnoseError> {
    let start = Params::nominal();
    let set = EffectSet::bind(in_model, campaign, &start)?;
    let mut copts = calib_options(opts);
    let (cal, est) = calib::calibrate(&Request {
        effects: &set,
        noise: opts.weighting,
        first_round: first,
        ..Request::new(campaign, &start, &copts)
    })
    .map_err(DiagnoseError::Baseline)?;
    copts.noise = est.model.clone();
    Ok((cal, est, copts))
}

/// The baseline's figures: its fit, the noise floor, and χ² against the stated noise.
fn baseline(
    base: &Fitted,
    estimated: &NoiseModel,
    val: Option<&Validation>,
    opts: &Options,
) -> Baseline {
    let noise_floor_um = match val {
        Some(v) => calib::rms(&v.sigma) * 1e3,
        None => calib::rms(&length_sigmas(&base.rows)) * 1e3,
    };
    let relative = val.map(|v| {
        (
            calib::rms(&base.fit.val_errors) * 1e3,
            calib::rms(&v.relative_sigma) * 1e3,
        )
    });
    // the same rows weighted by the rating: each group's variance part back at its rating
    let ratio2: [f64; N_GROUPS] = std::array::from_fn(|k| {
        let g = Group::ALL[k];
        (opts.noise.sigma(g, 1000.0) / estimated.sigma(g, 1000.0)).powi(2)
    });
    let scale: f64 = base
        .rows
        .iter()
        .map(|r| {
            let var: f64 = r.parts.iter().zip(&ratio2).map(|(v, f)| v * f).sum();
            r.value * r.value / var
        })
        .sum();
    let p_value = stats::chi2_upper_tail(scale, base.fit.dof);
    Baseline {
        cal_rms_um: base.fit.cal_rms_um,
        val_rms_um: base.fit.val_rms_um,
        noise_floor_um,
        val_rms_relative_um: relative.map(|r| r.0),
        noise_floor_relative_um: relative.map(|r| r.1),
        chi2: scale,
        dof: base.fit.dof,
        chi2_per_dof: scale / base.fit.dof,
        p_value,
        consistent_with_noise: p_value > opts.alpha,
        val_errors: base.fit.val_errors.clone(),
    }
}

fn noise_map(groups: &[GroupNoise]) -> BTreeMap<String, NoiseReport> {
    groups
        .iter()
        .map(|g| {
            (
                g.group.to_owned(),
                NoiseReport {
                    unit: g.unit,
                    assumed: g.assumed,
                    estimated: g.estimated,
                    dof: g.dof,
                },
            )
        })
        .collect()
}

/// A candidate whose screening fit leaves its F-test's p-value above this is no contender:
/// its figures are the screening fit's. Below it the candidate is fitted to convergence, so
/// that every candidate that can be significant (level α/m ≤ 1e-3) or can be the verdict is
/// judged on its converged fit. The screen's Δχ² is a lower bound of the converged one (the
/// screened point is one the converged fit could have stopped at), so the margin from
/// 1e-3 to 0.05 is for the linearisation alone: one step from the current model's minimum
/// moves the χ² within 1e-3 relative of the converged value on the twin's campaigns.
pub const SCREEN_P: f64 = 0.05;

impl Trials<'_> {
    /// Fit `effect` added to the model (`set`: the model with it, bound): the whole family,
    /// and the parts the data support. First one LM step from the current model's minimum
    /// (the candidate's own parameters at zero, nearly Gauss-Newton's step: the score test of
    /// the effect, linearised where the current model ended); a candidate that is then far
    /// from significance ([`SCREEN_P`]) keeps that fit, any other is fitted to convergence.
    fn try_effect(&self, effect: &dyn Effect, mut set: EffectSet) -> Tried {
        let (val, base, copts) = (self.val, self.base, &self.copts);
        let with = with_effect(self.in_model, effect);
        // the screening step; where the rows did not confirm it, this is the converged fit
        let cal = self.fit(&set, self.screen)?;
        let cal = if cal.screened {
            let screened = finish_with(val, &with, &set, cal, copts)?;
            if screen_p_value(base, &screened.fit) > SCREEN_P {
                let kept = Fitted {
                    rows: screened.rows.clone(),
                    fit: screened.fit.clone(),
                };
                return Ok((screened, kept));
            }
            // a contender: fitted to convergence from the current model, as without the
            // screen
            self.fit(&set, false)?
        } else {
            cal
        };
        // parts of the family the data do not support: held at zero in the kept variant
        let weak = weak_parts(&cal, &set, effect.name());
        let full = finish_with(val, &with, &set, cal, copts)?;
        if weak.is_empty() {
            let kept = Fitted {
                rows: full.rows.clone(),
                fit: full.fit.clone(),
            };
            return Ok((full, kept));
        }
        for k in weak {
            set.hold(k);
        }
        let cal = self.fit(&set, false)?;
        let kept = finish_with(val, &with, &set, cal, copts)?;
        Ok((full, kept))
    }

    /// The model `set` calibrated from the current model's minimum, its own parameters at
    /// zero (`screen`: [`calib::WarmStart::screen`]).
    fn fit(&self, set: &EffectSet, screen: bool) -> Result<Calibration, CalibrationError> {
        let (campaign, start, copts) = (self.campaign, &self.start, &self.copts);
        let theta = warm_theta(set, self.base);
        let warm = calib::WarmStart {
            params: &self.base.params,
            theta: &theta,
            screen,
        };
        calib::calibrate(&Request {
            effects: set,
            warm: Some(warm),
            shared: self.shared.as_ref(),
            ..Request::new(campaign, start, copts)
        })
        .map(|(cal, _)| cal)
    }
}

/// The nested F-test's p-value of a screening fit against the current model (1 when the
/// effect adds no effective parameter or lowers nothing: no contender).
fn screen_p_value(base: &Fit, screened: &Fit) -> f64 {
    let k = base.dof - screened.dof;
    let dchi2 = base.chi2 - screened.chi2;
    if k < 0.5 || !(dchi2 > 0.0) {
        return 1.0;
    }
    let f = (dchi2 / k) / (screened.chi2 / screened.dof);
    stats::f_upper_tail(f, k, screened.dof)
}

/// The current model's effect parameters (`base`) laid out for `set` (the same effects and a
/// candidate): each slot takes the value of the slot of the same effect and name, a slot
/// the current model does not have starts at zero.
fn warm_theta(set: &EffectSet, base: &Fit) -> Vec<f64> {
    set.layout()
        .iter()
        .map(|slot| {
            base.effect_params
                .iter()
                .find(|e| e.effect == slot.effect && e.name == slot.param.name)
                .map_or(0.0, |e| e.value)
        })
        .collect()
}

/// θ indexes of `effect`'s machine parameters below 2σ, when it has several identified (the
/// strongest is always kept).
fn weak_parts(cal: &Calibration, set: &EffectSet, effect: &str) -> Vec<usize> {
    let own: Vec<(usize, f64)> = set
        .layout()
        .iter()
        .filter(|slot| slot.effect == effect && !slot.setup_local)
        .filter(|slot| cal.effects[slot.index].identified)
        .map(|slot| {
            let e = &cal.effects[slot.index];
            (
                slot.index,
                if e.sigma > 0.0 {
                    (e.value / e.sigma).abs()
                } else {
                    0.0
                },
            )
        })
        .collect();
    if own.len() < 2 {
        return Vec::new();
    }
    let strongest = own.iter().map(|o| o.1).fold(0.0, f64::max);
    own.iter()
        .filter(|o| o.1 < 2.0 && o.1 < strongest)
        .map(|o| o.0)
        .collect()
}

/// A fit that failed.
#[derive(Debug, thiserror::Error)]
enum FitError {
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
    #[error(transparent)]
    Effect(#[from] NotApplicable),
    #[error(transparent)]
    Validation(#[from] PoseError),
}

/// Calibrate `campaign` with `effects` in the model as the diagnosis does (noise estimated,
/// tolerance prior) and evaluate it on the held-out data: the statistics of one model
/// (`rpkm calibrate --effects`).
pub fn evaluate(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    effects: &[&dyn Effect],
    opts: &Options,
) -> Result<(Fit, NoiseEstimate), DiagnoseError> {
    let (cal, est, copts) = current_model(campaign, effects, opts, None)?;
    let val = held_out(validation, &est.model)?;
    Ok((
        finish(campaign, val.as_ref(), effects, cal, &copts)?.fit,
        est,
    ))
}

/// The TCP error of one pose of a 2-D relative instrument (laser tracker, grid encoder) as a
/// vector: the model's TCP displacement from the setup's reset pose minus the instrument's
/// reading (µm), where the pose and its reset pose are (nominal forward model, mm). The
/// classic picture of a calibration: an arrow per pose over the workspace.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ErrorVector {
    pub pose: usize,
    pub line: usize,
    pub instrument: String,
    pub setup: String,
    pub x: f64,
    pub y: f64,
    pub reset_x: f64,
    pub reset_y: f64,
    pub dx_um: f64,
    pub dy_um: f64,
}

/// The error vectors of every 2-D relative pose of `campaign` under the calibration `cal` of
/// the model with `effects`.
fn error_vectors(
    campaign: &Campaign,
    effects: &[&dyn Effect],
    cal: &Calibration,
    model: Model,
) -> Result<Vec<ErrorVector>, DiagnoseError> {
    let set = EffectSet::bind(effects, campaign, &cal.start)?;
    let errs = obs::tcp_errors_with(campaign, &cal.params, model, &set.corrections(&cal.theta))
        .map_err(DiagnoseError::Vectors)?;
    let mut xy: BTreeMap<usize, [Option<f64>; 2]> = BTreeMap::new();
    for e in &errs {
        let slot = xy.entry(e.pose).or_default();
        match e.coordinate {
            "x" => slot[0] = Some(e.value * 1e3),
            "y" => slot[1] = Some(e.value * 1e3),
            _ => {}
        }
    }
    let tcp = sparse::nominal_tcp(campaign);
    let mut out = Vec::new();
    for setup in campaign.setups() {
        let Some(reset) = setup.reset else { continue };
        for &i in &setup.poses {
            // a tracker or grid-encoder pose gives both coordinates; a single one is no vector
            let Some([Some(dx_um), Some(dy_um)]) = xy.get(&i).copied() else {
                continue;
            };
            let pose = &campaign.poses[i];
            out.push(ErrorVector {
                pose: i,
                line: pose.line,
                instrument: pose.instrument.as_str().to_owned(),
                setup: setup.id.to_owned(),
                x: tcp[i].0,
                y: tcp[i].1,
                reset_x: tcp[reset].0,
                reset_y: tcp[reset].1,
                dx_um,
                dy_um,
            });
        }
    }
    Ok(out)
}

/// The held-out campaign with the noise of each of its TCP errors.
fn held_out<'a>(
    validation: Option<&'a Campaign>,
    noise: &NoiseModel,
) -> Result<Option<Validation<'a>>, DiagnoseError> {
    validation
        .map(|v| Validation::new(v, noise))
        .transpose()
        .map_err(DiagnoseError::Validation)
}

impl From<FitError> for DiagnoseError {
    /// A failed fit of the model being diagnosed.
    fn from(e: FitError) -> Self {
        match e {
            FitError::Calibration(c) => DiagnoseError::Baseline(c),
            FitError::Effect(n) => DiagnoseError::Effect(n),
            FitError::Validation(v) => DiagnoseError::Validation(v),
        }
    }
}

/// The statistics of a calibration with `effects` (bound again to read its layout).
fn finish(
    campaign: &Campaign,
    val: Option<&Validation>,
    effects: &[&dyn Effect],
    cal: Calibration,
    copts: &calib::Options,
) -> Result<Fitted, FitError> {
    let set = EffectSet::bind(effects, campaign, &cal.start)?;
    finish_with(val, effects, &set, cal, copts)
}

/// The statistics of a calibration `cal` of the effects bound in `set`.
fn finish_with(
    val: Option<&Validation>,
    effects: &[&dyn Effect],
    set: &EffectSet,
    cal: Calibration,
    copts: &calib::Options,
) -> Result<Fitted, FitError> {
    let val_errors = val
        .map(|v| held_out_values(v, effects, set, &cal, copts.model))
        .transpose()?;
    let val_rms_um = val_errors.as_ref().map(|e| calib::rms(e) * 1e3);
    let val_errors = val.zip(val_errors).map(|(v, e)| v.relative(&e));
    // The calibration is spent here: its rows and parameters move into the fit.
    let rows = cal.residuals;
    let chi2: f64 = rows.iter().map(|r| (r.value / r.sigma).powi(2)).sum();
    let dof = (rows.len() as f64 - cal.dof_model).max(1.0);
    let fit = Fit {
        chi2,
        dof,
        chi2_per_dof: chi2 / dof,
        cal_rms_um: calib::rms(&length_values(&rows)) * 1e3,
        val_rms_um,
        val_errors: val_errors.unwrap_or_default(),
        effect_params: cal.effects,
        determined: cal.determined,
        params: cal.params,
        theta: cal.theta,
    };
    Ok(Fitted { rows, fit })
}

/// Calibration options of the diagnosis: the model's links, every parameter under its
/// tolerance prior, no outlier elimination (the nested tests need the same rows in every
/// fit). `rpkm calibrate` and the calibrator node calibrate with the same selection.
pub fn calib_options(opts: &Options) -> calib::Options {
    calib::Options {
        model: Model::M29,
        selection: calib::Selection::Prior(opts.prior),
        links: match opts.model {
            Model::M24 => calib::Link::perfect_parallelogram(),
            Model::M29 => Vec::new(),
        },
        outlier_sigma: None,
        noise: opts.noise.clone(),
        stop: opts.stop.clone(),
        ..Default::default()
    }
}

/// The held-out TCP errors (mm, in [`obs::tcp_errors`] order) of a calibration `cal` of the
/// model with `effects` (bound to the calibration's campaign as `cal_set`), the held-out
/// rows weighted by `noise`: what `rpkm calibrate --effects ... --validate` reports.
pub fn held_out_errors(
    validation: &Campaign,
    noise: &NoiseModel,
    effects: &[&dyn Effect],
    cal_set: &EffectSet,
    cal: &Calibration,
) -> Result<Vec<f64>, DiagnoseError> {
    let val = Validation::new(validation, noise).map_err(DiagnoseError::Validation)?;
    Ok(held_out_values(&val, effects, cal_set, cal, cal.model)?)
}

/// The held-out TCP errors (mm) with the calibrated model and effects; the effects'
/// setup-local parameters are re-fitted on the held-out setups (Gauss-Newton).
fn held_out_values(
    val: &Validation,
    effects: &[&dyn Effect],
    cal_set: &EffectSet,
    cal: &Calibration,
    model: Model,
) -> Result<Vec<f64>, FitError> {
    let set = EffectSet::bind(effects, val.campaign, &cal.params)?;
    let cal_layout = cal_set.layout();
    let layout = set.layout();
    // machine parameters carry over by name; setup-local ones start at zero
    let mut theta: Vec<f64> = layout
        .iter()
        .map(|slot| {
            if slot.setup_local {
                return 0.0;
            }
            cal_layout
                .iter()
                .find(|c| c.effect == slot.effect && c.param.name == slot.param.name)
                .map_or(0.0, |c| cal.theta[c.index])
        })
        .collect();
    let local: Vec<usize> = layout
        .iter()
        .filter(|slot| slot.setup_local)
        .map(|slot| slot.index)
        .collect();
    let weights: Vec<f64> = val.sigma.iter().map(|s| 1.0 / s).collect();
    for _ in 0..if local.is_empty() { 0 } else { 5 } {
        let errs =
            obs::tcp_errors_with(val.campaign, &cal.params, model, &set.corrections(&theta))?;
        let j = DMatrix::from_fn(errs.len(), local.len(), |i, k| {
            errs[i].d_theta[local[k]] * weights[i]
        });
        let r = DVector::from_iterator(
            errs.len(),
            errs.iter().zip(&weights).map(|(e, w)| e.value * w),
        );
        let Some(step) = (j.transpose() * &j)
            .cholesky()
            .map(|c| c.solve(&(j.transpose() * r)))
        else {
            break;
        };
        for (k, &t) in local.iter().enumerate() {
            theta[t] -= step[k];
        }
    }
    let errs = obs::tcp_errors_with(val.campaign, &cal.params, model, &set.corrections(&theta))?;
    Ok(errs.iter().map(|e| e.value).collect())
}

/// σ of every held-out TCP error, in [`obs::tcp_errors`] order: the instrument's noise at the
/// pose and at its setup's reset pose (zeroed on a reading as noisy as any other), and the
/// encoders' at both.
/// The variance of one held-out TCP error: its own reading's and the reading its setup was
/// zeroed on (every error of the setup shares that one draw).
struct ErrorVariance {
    reading: f64,
    zero: f64,
}

fn validation_variances(
    val: &Campaign,
    errs: &[(usize, &'static str, f64)],
    noise: &NoiseModel,
) -> Result<Vec<ErrorVariance>, PoseError> {
    let nominal = Params::nominal();
    let mut reset_of = vec![None; val.poses.len()];
    for setup in val.setups() {
        for &i in &setup.poses {
            reset_of[i] = setup.reset;
        }
    }
    let variance = |i: usize, coordinate: &str| -> Result<f64, PoseError> {
        let pose = &val.poses[i];
        let tcp = geometry::fgm(&nominal, Model::M29, pose.q[0], pose.q[3])
            .map_err(|e| PoseError::at(val, pose, e))?;
        let cov = |xy| noise.xy_covariance(xy, Vector2::new(tcp.x(), tcp.y()));
        let reading = match (coordinate, XyInstrument::of(pose.instrument)) {
            ("x", Some(xy)) => cov(xy)[(0, 0)],
            ("y", Some(xy)) => cov(xy)[(1, 1)],
            _ => noise.scalar_sigma(pose.instrument).unwrap_or(0.0).powi(2),
        };
        Ok(reading + noise.encoder_mm.powi(2))
    };
    errs.iter()
        .map(|(i, coordinate, _)| {
            // the reading the setup was zeroed on is in every error of the setup (none for a
            // ball-bar, zeroed on no reading; the reset's encoders for every instrument)
            let zero = match reset_of[*i] {
                Some(r) if val.poses[r].instrument == Instrument::Dbb => noise.encoder_mm.powi(2),
                Some(r) => variance(r, coordinate)?,
                None => 0.0,
            };
            Ok(ErrorVariance {
                reading: variance(*i, coordinate)?,
                zero,
            })
        })
        .collect()
}

/// The candidate's comparison with the current model (the F-test on the whole family
/// `full`, the figures of the parts `kept`); None if the effect added no parameter.
fn compare(
    base: &Fitted,
    full: &Fitted,
    kept: &Fitted,
    effect: &dyn Effect,
    campaign: &Campaign,
    level: f64,
) -> Option<Candidate> {
    let k = base.fit.dof - full.fit.dof;
    if k < 0.5 {
        return None;
    }
    let dchi2 = base.fit.chi2 - full.fit.chi2;
    let f = (dchi2 / k) / (full.fit.chi2 / full.fit.dof);
    let p_value = stats::f_upper_tail(f, k, full.fit.dof);
    let kept_k = (base.fit.dof - kept.fit.dof).max(0.0);
    let kept_dchi2 = base.fit.chi2 - kept.fit.chi2;
    let excess = base.fit.chi2 - base.fit.dof;
    let explained_fraction = if excess > 0.0 {
        (kept_dchi2 / excess).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let n = base.rows.len() as f64;
    let name = effect.name();
    let params: Vec<EffectEstimate> = kept
        .fit
        .effect_params
        .iter()
        .filter(|e| e.effect == name)
        .cloned()
        .collect();
    let follows = sparse::follows(campaign, &base.rows, effect.covariates());
    let relevant = params
        .iter()
        .filter(|p| p.identified && p.prior > 0.0)
        .any(|p| p.value.abs() >= RELEVANT_FRACTION * p.prior);
    Some(Candidate {
        effect: name.to_owned(),
        significant: p_value < level,
        relevant,
        explained_fraction,
        val_rms_before_um: base.fit.val_rms_um,
        val_rms_after_um: full.fit.val_rms_um,
        chi2_per_dof_after: kept.fit.chi2_per_dof,
        f_statistic: f,
        f_dof: (k, full.fit.dof),
        p_value,
        bic_gain: kept_dchi2 - kept_k * n.ln(),
        params,
        chi2_per_dof_before: base.fit.chi2_per_dof,
        follows,
        // judged as the loop will add it: the whole family (the next diagnosis fits every
        // part), not the parts this campaign supports
        prediction: Prediction::of(&base.fit.val_errors, &full.fit.val_errors),
        cross_validated: None,
        together: None,
    })
}

/// Values (mm) of the length rows (not ψ, not forces).
fn length_values(rows: &[RowValue]) -> Vec<f64> {
    rows.iter()
        .filter(|r| r.direction.is_length())
        .map(|r| r.value)
        .collect()
}

fn length_sigmas(rows: &[RowValue]) -> Vec<f64> {
    rows.iter()
        .filter(|r| r.direction.is_length())
        .map(|r| r.sigma)
        .collect()
}

fn groups(rows: &[RowValue]) -> Vec<GroupRms> {
    /// Sums over the rows of one instrument and direction.
    #[derive(Default)]
    struct Sums {
        rows: usize,
        value2: f64,
        sigma2: f64,
        chi2: f64,
    }
    let mut acc: std::collections::BTreeMap<(String, String), (Sums, f64)> =
        std::collections::BTreeMap::default();
    for r in rows {
        let (e, scale) = acc
            .entry((r.instrument.as_str().to_owned(), r.direction.to_string()))
            .or_default();
        *scale = r.direction.report_unit().0;
        e.rows += 1;
        e.value2 += r.value * r.value;
        e.sigma2 += r.sigma * r.sigma;
        e.chi2 += (r.value / r.sigma).powi(2);
    }
    acc.into_iter()
        .map(|((instrument, direction), (sum, scale))| {
            let n = sum.rows as f64;
            GroupRms {
                instrument,
                direction,
                rows: sum.rows,
                rms: (sum.value2 / n).sqrt() * scale,
                noise: (sum.sigma2 / n).sqrt() * scale,
                chi2_per_row: sum.chi2 / n,
            }
        })
        .collect()
}

fn points(campaign: &Campaign, rows: &[RowValue]) -> Vec<Point> {
    let tcp = sparse::nominal_tcp(campaign);
    let mut out: Vec<Point> = rows
        .iter()
        .map(|r| {
            let pose = &campaign.poses[r.pose];
            let (x, y) = tcp[r.pose];
            Point {
                pose: r.pose,
                line: pose.line,
                instrument: r.instrument.as_str().to_owned(),
                direction: r.direction.to_string(),
                x,
                y,
                t: pose.t,
                value: r.value * r.direction.report_unit().0,
                sigma: r.sigma * r.direction.report_unit().0,
            }
        })
        .collect();
    out.sort_by(|a, b| {
        (b.value / b.sigma)
            .abs()
            .total_cmp(&(a.value / a.sigma).abs())
    });
    out
}
