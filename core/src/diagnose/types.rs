//! The diagnosis's vocabulary: its options, errors and results. Every stage reads this file;
//! it reads none of them.

use super::{structure::neighbours, structure::periodic, structure::sparse};
use crate::calib::{self, CalibrationError, EffectEstimate, Prior};
use crate::effects::NotApplicable;
use crate::noise::NoiseModel;
use crate::obs::{PoseError, RowValue};
use crate::params::{Model, Params};
use crate::variance::GroupNoise;
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
pub struct DiagnosisOptions {
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

impl DiagnosisOptions {
    /// Whether the caller asked the diagnosis to stop ([`DiagnosisOptions::stop`]).
    pub(crate) fn stopped(&self) -> bool {
        self.stop.as_ref().is_some_and(calib::Stop::requested)
    }
}

impl Default for DiagnosisOptions {
    fn default() -> Self {
        DiagnosisOptions {
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
    /// RMS of the length rows of the calibration (mm; µm in the JSON).
    #[serde(rename = "cal_rms_um", serialize_with = "as_um")]
    pub cal_rms: f64,
    /// The held-out figures (errors, their RMS, floors), if there are held-out data.
    #[serde(skip)]
    pub held_out: Option<super::held_out::figures::HeldOut>,
    /// Effect parameters of each setup (an instrument's alignment in that mounting): on the
    /// held-out campaign they are fitted to its own readings.
    #[serde(skip)]
    pub setup_params: usize,
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
    /// Covariance of `theta` (zero rows and columns where a parameter is not identified):
    /// the Wald test of the parameters added ([`super::search::gain`]).
    #[serde(skip)]
    pub covariance_theta: nalgebra::DMatrix<f64>,
}

/// The current model's fit and its test against the stated noise (the JSON's `baseline`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Baseline {
    #[serde(rename = "cal_rms_um", serialize_with = "as_um")]
    pub cal_rms: f64,
    #[serde(rename = "val_rms_um", serialize_with = "as_um")]
    pub val_rms: Option<f64>,
    /// RMS that noise alone would give on the held-out errors (or, without held-out data, on
    /// the calibration's length rows), mm (µm in the JSON), at the estimated noise levels. It counts the
    /// reading each setup was zeroed on at its variance, but all the poses of a setup share
    /// that one draw: with few setups the held-out RMS strays from it by that draw.
    #[serde(rename = "noise_floor_um", serialize_with = "as_um")]
    pub noise_floor: f64,
    /// The held-out RMS with each setup's zero removed (its errors less their mean, per
    /// coordinate: what a model can predict), mm (µm in the JSON), and the RMS noise alone would
    /// give there:
    /// the zero reading cancels, so they compare like with like whatever it drew.
    #[serde(rename = "val_rms_relative_um", serialize_with = "as_um")]
    pub val_rms_relative: Option<f64>,
    #[serde(rename = "noise_floor_relative_um", serialize_with = "as_um")]
    pub noise_floor_relative: Option<f64>,
    /// χ² against the stated (not the estimated) noise, its dof and p-value: how the
    /// residual compares with the instruments' rating. Not used by the verdict.
    pub chi2: f64,
    pub dof: f64,
    pub chi2_per_dof: f64,
    /// P(χ²_ν ≥ χ²): small when the residual is more than the rated noise.
    pub p_value: f64,
    pub consistent_with_noise: bool,
    /// The held-out figures the RMS and floors above are of: the errors (mm) with their
    /// setups' zeros removed compare the models of successive diagnoses pose by pose
    /// ([`Prediction::of`]).
    #[serde(skip)]
    pub held_out: Option<super::held_out::figures::HeldOut>,
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
    #[serde(rename = "val_rms_before_um", serialize_with = "as_um")]
    pub val_rms_before: Option<f64>,
    #[serde(rename = "val_rms_after_um", serialize_with = "as_um")]
    pub val_rms_after: Option<f64>,
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
    /// The evidence of both campaigns, whether it matters, whether its values are physical,
    /// and what the model search made of it.
    #[serde(flatten)]
    pub judged: Judged,
}

impl Candidate {
    /// How the candidate alone predicts: the held-out comparison where it decides (better,
    /// or clearly worse), else cross-validation by setup.
    pub fn alone(&self) -> Option<Prediction> {
        self.prediction
            .filter(Prediction::decides)
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
    /// µm (held-out TCP errors) or σ (held-out errors or left-out rows of every instrument,
    /// each in its own noise).
    pub unit: RmsUnit,
    /// How strongly the errors before support the change the larger model makes to them,
    /// as a one-sided p-value: the errors regressed on that change (one coefficient), whose
    /// t-value is N(0, 1) where the change is not in the data (it comes from the other
    /// campaign, or other setups) and large where the data show it, even where the change's
    /// size, fitted on the calibration campaign, is still uncertain. Where the larger model
    /// fits parameters of its own to the compared setups (`refitted`), its change there is
    /// partly fitted to the very errors and follows them by construction: the fall of their
    /// mean square beyond what fitting that many parameters to noise takes, in its standard
    /// error, instead ([`Prediction::refit`]).
    pub support_p: f64,
    /// Parameters of the larger model fitted to the compared errors themselves (the
    /// held-out setups' own alignment, say); 0 for none.
    pub refitted: usize,
    /// The RMS fell by more than its standard error.
    pub better: bool,
    /// The RMS rose by more than twice its standard error: clearly worse (a rise within
    /// that is a tie, which the held-out data do not decide: an effect they do not see
    /// would otherwise be refused one time in six by chance).
    pub worse: bool,
    /// The RMS's fall as `better` and `worse` read it (in µm where the rest compares the
    /// held-out errors in σ): not above zero where it did not fall at all.
    pub fall_read: f64,
    /// Judged by cross-validation by setup on the calibration campaign.
    pub by_setup: bool,
    /// How clearly the compared errors would follow the change if it were right: its size
    /// over the errors' RMS, √ΣΔ² / s, the regression's expected t-value under the change
    /// (0 where nothing changes).
    pub resolution: f64,
}

/// A family whose parts the campaigns do not decide: the calibration needs a combination of
/// more parts than the one settled, and that combination predicts worse (held-out data, or
/// the setups cross-validation leaves out). The settle keeps the smaller; the user learns that
/// neither is determined.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Undecided {
    /// The part combination settled (`thermal:scales`, with `thermal_lag:scales` where the
    /// lag is in the model: it takes the parts `thermal` is tried with).
    pub settled: Vec<String>,
    /// The one of more parts the calibration needs over it, of physical values
    /// (`thermal:rods+frame+scales`, its lag alike).
    pub needed: Vec<String>,
    /// Its calibration χ²'s fall under the settled one's, the parameters it adds, and the
    /// nested F-test's p-value.
    pub chi2_fall: f64,
    pub added: f64,
    pub p_value: f64,
    /// The prediction from the settled combination (before) to the needed one (after).
    pub prediction: Prediction,
}

/// How an addition to the model fares on both campaigns (a candidate alone, or a
/// combination the model search tried).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Judged {
    /// Fisher's combination of the calibration campaign's F-test and the prediction's
    /// one-sided test (held-out data, else cross-validation by setup): the evidence of both
    /// campaigns, compared with the candidates' level. The F-test's p alone where nothing
    /// predicts.
    pub evidence_p: f64,
    /// What `evidence_p` combines: the fit with the held-out prediction, with the
    /// cross-validation by setup, or the fit alone.
    pub evidence_of: EvidenceOf,
    /// RMS of the prediction error the addition explains, √(RMS_b² − RMS_a²), over the
    /// noise there (the held-out floor, or 1 for left-out rows in σ); on the calibration's
    /// rows where nothing predicts.
    pub size: Option<f64>,
    /// Whether it matters: `size` reaches [`super::search::gain::PRACTICAL_SIZE`].
    pub matters: bool,
    /// Effect parameters fitted clearly outside the values the physics allows (more than
    /// 3σ): "alpha_rods = -275 ± 27 ppm/K outside -5..40".
    pub implausible: Vec<String>,
    /// What the model search made of it.
    pub outcome: Outcome,
}

impl Default for Judged {
    fn default() -> Self {
        Judged {
            evidence_p: 1.0,
            evidence_of: EvidenceOf::FitAlone,
            size: None,
            matters: false,
            implausible: Vec::new(),
            outcome: Outcome::NotSignificant,
        }
    }
}

/// The campaigns an addition's evidence rests on (JSON: snake case).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EvidenceOf {
    /// The calibration's F-test with the prediction of the held-out campaign.
    FitAndHeldOut,
    /// The calibration's F-test with the prediction of left-out setups of the same campaign.
    FitAndCrossValidation,
    /// The calibration's F-test alone: nothing predicted.
    FitAlone,
}

impl EvidenceOf {
    /// The evidence of a gain with this `prediction` (none: the fit alone).
    pub fn of(prediction: Option<&Prediction>) -> EvidenceOf {
        match prediction {
            Some(p) if p.by_setup => EvidenceOf::FitAndCrossValidation,
            Some(_) => EvidenceOf::FitAndHeldOut,
            None => EvidenceOf::FitAlone,
        }
    }
}

/// Why an addition to the model was or was not named (JSON: snake case).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// The model the diagnosis names (alone or with its partner).
    Named,
    /// Predicts within one standard error of the model named, which is simpler.
    SimplerNamed,
    /// Predicts worse than the model named by more than a standard error.
    Outpredicted,
    /// The evidence of both campaigns is short of the level.
    NotSignificant,
    /// The held-out (or left-out) data predict clearly worse with it.
    Contradicted,
    /// Significant, but it does not predict better.
    NoBetter,
    /// A model of several effects that predicts no better than without one of them.
    MemberAddsNothing,
    /// A model that holds it and more (another part of a family, another effect) beats it:
    /// it leaves out something that earns its place.
    Incomplete,
    /// Statistically detectable, too small to matter.
    TooSmall,
    /// Fitted values outside what the physics allows: it absorbs something else.
    Implausible,
    /// No parameter of it reaches a twentieth of its plausible size.
    Irrelevant,
    /// A single term of the residual's dictionary explains as much, and the effect leaves
    /// structure behind.
    OutdoneByTerm,
}

/// One model the search tried: the current model with `added`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModelTrial {
    /// The effects added (a family's parts pinned: `thermal:rods`).
    pub added: Vec<String>,
    /// A family of the current model fitted with other parts than it settled to, in its
    /// place (`thermal:rods+frame`): the parts a family keeps may change with the effect
    /// added.
    pub instead: Option<String>,
    /// Parameters it adds (effective: what the data determine).
    pub k: f64,
    /// Nested F-test against the current model on the calibration campaign; `p_value` the
    /// larger of its p-value and `wald_p`.
    pub f_statistic: f64,
    pub p_value: f64,
    /// The Wald test of the added parameters themselves: large where they trade off against
    /// each other or the geometry, however large F (the fit improves, no parameter is pinned).
    pub wald_p: f64,
    /// The F-test's own p-value.
    pub f_p: f64,
    pub chi2_per_dof_after: f64,
    /// The prediction of held-out (or left-out) data against the current model's.
    pub prediction: Option<Prediction>,
    /// The added effects' parameters as fitted.
    pub params: Vec<EffectEstimate>,
    #[serde(flatten)]
    pub judged: Judged,
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
pub struct ResidualPoint {
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

/// The unit of a [`Prediction`]'s RMS (the JSON's `unit`: `um`, `sigma`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RmsUnit {
    /// Held-out TCP errors, µm.
    Um,
    /// Errors each in its own noise.
    Sigma,
}

impl std::fmt::Display for RmsUnit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(match self {
            RmsUnit::Um => "um",
            RmsUnit::Sigma => "sigma",
        })
    }
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
    /// `estimated` is the estimation's cap, not an estimate ([`crate::variance::GroupNoise::capped`]).
    pub capped: bool,
}

/// The diagnosis (serialises to the JSON other tools read: `verdict_kind`, `missing_effect`,
/// `noise`, `baseline`, `candidates`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModelDiagnosis {
    /// Written as the thesis names it (`model 24`).
    #[serde(serialize_with = "as_words")]
    pub model: Model,
    /// The effects in the model as given (`--effects`).
    pub effects_in_model: Vec<String>,
    /// The same as fitted: a family named whole keeps the parts the data can tell apart
    /// (`thermal` fitted as `thermal:rods`), an effect the refinement they need
    /// (`preload_elastic` as `preload_elastic:rod3`).
    pub model_effects: Vec<String>,
    /// The current model's effect parameters as fitted: value, σ and unit.
    pub effect_values: Vec<EffectEstimate>,
    pub verdict_kind: VerdictKind,
    /// The effect to add (`--effects` takes it; a family by its name, its parts left to the
    /// data), the first of `missing_effects`.
    pub missing_effect: Option<String>,
    /// The model the diagnosis names, whole: every effect to add, a family's parts as the
    /// search chose them (`thermal:rods`, `preload_elastic`).
    pub missing_effects: Vec<String>,
    /// χ²/dof of the current model at the estimated noise (near 1 when nothing is missing).
    pub chi2_per_dof: f64,
    /// The current model's calibrated geometric parameters (mm, rad) by name: the
    /// calibration the verdict rests on, the one `rpkm calibrate` makes with the same options.
    pub parameters: BTreeMap<String, f64>,
    /// Per group: the stated and the estimated noise, under the current model (the
    /// baseline's: the same whatever candidates are offered).
    pub noise: BTreeMap<String, NoiseReport>,
    /// The candidates were compared with the rows weighted by the noise estimated under the
    /// current model with these (significant at the stated noise, fitted together): a model
    /// that misses an effect would count it as noise. Empty: the current model's own noise.
    pub compared_under: Vec<String>,
    /// The same, with whether each was estimated from the data.
    #[serde(skip)]
    pub noise_groups: Vec<GroupNoise>,
    /// Parameter combinations the campaign determined better than their tolerance, of how
    /// many (the rest stayed at the prior).
    pub determined: Option<(usize, usize)>,
    pub baseline: Baseline,
    /// The held-out judge on the current model (None without held-out data): the model
    /// explains the calibration campaign, and the held-out data agree, or do not.
    pub held_out: Option<HeldOutCheck>,
    pub candidates: Vec<Candidate>,
    /// The models the search tried beyond single candidates: a family's parts, pairs.
    pub trials: Vec<ModelTrial>,
    pub skipped: Vec<Skipped>,
    /// The dictionary test of the current model's residual.
    pub structure: sparse::Structure,
    /// The strongest period of the current model's residual in a carrier's position.
    pub periodic: Option<periodic::Periodic>,
    /// Where the model reads a thermometer's history: the part of the residual its readings'
    /// noise makes through that history, taken out before the structure tests
    /// ([`super::structure::carried`]).
    pub carried: Option<super::structure::carried::Carried>,
    /// The direction whose residuals are most alike along the setups' paths.
    pub neighbours: Option<neighbours::Neighbours>,
    /// The dictionary term that explained the residual as well as the named effect: the
    /// effect was preferred because it predicts held-out data, which a term cannot.
    pub tied_term: Option<String>,
    /// The part combination of a family of the current model that the named model fits in
    /// place of the one settled (`thermal:frame+scales` where the model has `thermal:scales`):
    /// the effects named predict only with it; the next diagnosis settles the family again.
    pub resettled: Option<String>,
    /// The families of the current model whose parts the campaigns do not decide: the
    /// calibration needs more parts than were settled, which predict worse.
    pub undecided: Vec<Undecided>,
    /// The second missing effect, where the model named holds two (alone, each absorbs part
    /// of the other): add both.
    pub together_with: Option<String>,
    /// Noise groups estimated more than [`NOISIER_THAN_RATED`] times their rating: either
    /// the instrument is that noisy or something is missing that the tests cannot see.
    pub noisier_than_rated: Vec<Noisier>,
    /// What the residual left by the verdict's model follows, when it is still structured.
    pub unexplained: Option<sparse::Pointer>,
    pub groups: Vec<GroupRms>,
    /// Residuals of the current model, worst (largest |r/σ|) first.
    pub points: Vec<ResidualPoint>,
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
    /// Level of the held-out χ² test against the model's floor.
    pub held_out_level: f64,
    /// Rows of the calibration.
    pub rows: usize,
}

/// A fit that failed.
#[derive(Debug, thiserror::Error)]
pub(crate) enum FitError {
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
    #[error(transparent)]
    Effect(#[from] NotApplicable),
    #[error(transparent)]
    Validation(#[from] PoseError),
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

/// What one fit produced: its final rows and statistics.
pub(crate) struct Fitted {
    /// The calibration's rows, shared by the entries of a search that hold the same fit (a
    /// candidate, its kept parts where none were dropped, its entry in the model search):
    /// one copy per fit, not per holder.
    pub rows: std::sync::Arc<Vec<RowValue>>,
    pub fit: Fit,
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
    /// The estimate is the estimation's cap: the ratio is a lower bound.
    pub capped: bool,
}

/// The TCP error of one pose of a 2-D relative instrument (laser tracker, grid encoder) as a
/// vector: the model's TCP displacement from the setup's reset pose minus the instrument's
/// reading (mm; µm in the JSON), where the pose and its reset pose are (nominal forward
/// model, mm). The
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
    #[serde(rename = "dx_um", serialize_with = "as_um")]
    pub dx: f64,
    #[serde(rename = "dy_um", serialize_with = "as_um")]
    pub dy: f64,
}

/// The figures of one calibrated model on held-out data, and the judge's test of them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct HeldOutCheck {
    /// The figures judged: the errors (mm), their RMS as measured and with each setup's zero
    /// removed, and what noise alone gives there (the JSON's `rms_um`, `rms_relative_um`,
    /// `noise_floor_um`, `noise_floor_relative_um`, in µm as every length of this struct).
    #[serde(flatten, serialize_with = "figures_as_um")]
    pub figures: super::held_out::figures::HeldOut,
    /// The floor of this calibrated model with each setup's zero removed: the noise, what
    /// the calibration's own uncertainty predicts at these poses, and what the held-out
    /// campaign's own nuisances do at their priors (`nuisance_terms`: a thermometer's error
    /// modes there).
    #[serde(rename = "floor_relative_um", serialize_with = "as_um")]
    pub floor_relative: f64,
    /// rᵀ V⁻¹ r of the zero-removed errors r against that floor in full (V: the noise and
    /// the calibration's uncertainty, which neighbouring poses share, so one error of it
    /// counts once), scaled to its degrees of freedom (the errors less the setups' zeros),
    /// and the noise estimate's own degrees of freedom (the floor is estimated too; infinite
    /// where the noise was stated).
    pub statistic: f64,
    pub dof: f64,
    pub noise_dof: f64,
    /// P(F ≥ statistic/dof) under a right model: small when the held-out errors are larger
    /// than the model's floor.
    pub p_value: f64,
    /// The RMS is what the model's floor gives (p above the level).
    pub consistent: bool,
    /// The held-out residual's structure: the dictionary (with the time since each setup's
    /// zero and the temperatures), the neighbours along each setup's path, the periods.
    pub structure_p: f64,
    pub structured: bool,
    /// The term the held-out residual follows most, where it follows one.
    pub follows: Option<sparse::Pointer>,
    /// How many nuisances of the held-out campaign's own (anchored) are in the floor.
    pub nuisance_terms: usize,
}

impl HeldOutCheck {
    /// Whether the held-out data agree with the model: at its floor and following nothing.
    pub fn agrees(&self) -> bool {
        self.consistent && !self.structured
    }

    /// RMS of the held-out TCP errors (mm) as measured, and with each setup's zero removed.
    pub fn rms(&self) -> f64 {
        self.figures.errors.rms
    }

    pub fn rms_relative(&self) -> f64 {
        self.figures.errors.rms_relative
    }

    /// What noise alone gives there (mm): counting each setup's zero reading (which all its
    /// readings share, so with few setups the raw RMS strays from it by that one draw), and
    /// with each setup's zero removed.
    pub fn noise_floor(&self) -> f64 {
        self.figures.noise_floor
    }

    pub fn noise_floor_relative(&self) -> f64 {
        self.figures.noise_floor_relative
    }
}

/// A judge's figures as its JSON writes them (µm), beside the judge's own keys.
fn figures_as_um<S: serde::Serializer>(
    h: &super::held_out::figures::HeldOut,
    s: S,
) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeMap;
    let um = crate::units::um_from_mm;
    let mut map = s.serialize_map(Some(4))?;
    map.serialize_entry("rms_um", &um(h.errors.rms))?;
    map.serialize_entry("rms_relative_um", &um(h.errors.rms_relative))?;
    map.serialize_entry("noise_floor_um", &um(h.noise_floor))?;
    map.serialize_entry("noise_floor_relative_um", &um(h.noise_floor_relative))?;
    map.end()
}

/// A length of the core (mm), or one that may be absent, as the JSON writes it (µm).
pub(crate) trait WrittenInUm {
    fn write_um<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error>;
}

impl WrittenInUm for f64 {
    fn write_um<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(crate::units::um_from_mm(*self))
    }
}

impl WrittenInUm for Option<f64> {
    fn write_um<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Some(mm) => s.serialize_some(&crate::units::um_from_mm(*mm)),
            None => s.serialize_none(),
        }
    }
}

/// A length of the core (mm) written as a person reads it (µm): the JSON's `*_um` keys.
pub(crate) fn as_um<L: WrittenInUm, S: serde::Serializer>(mm: &L, s: S) -> Result<S::Ok, S::Error> {
    mm.write_um(s)
}

/// A value serialised as its words (a model as `model 24`).
fn as_words<T: std::fmt::Display, S: serde::Serializer>(v: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}
