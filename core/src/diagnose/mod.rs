//! Model discovery: where the model fails, which physical effect is missing, and what the
//! held-out error becomes once it is added. No step hinges on an assumed noise level.
//!
//! The stages, one file each:
//!
//! - [`rounds`]: the flow. Every candidate at the stated noise first (which stand out), the
//!   current model on its own, then the candidates again under the noise estimated with
//!   those that stood out.
//! - [`current`]: the current model as every command evaluates it: its noise estimated from
//!   the campaign, a family named whole settled to the parts the data can tell apart, its
//!   held-out figures ([`evaluate`], which `rpkm calibrate`'s table of stages uses).
//! - [`trials`]: each effect of the library (and the user's written ones) added and fitted,
//!   screened by one Gauss-Newton step, compared by the nested F-test
//!   F = (Δχ²/k) / (χ²₁/ν₁), free of the noise's absolute level.
//! - [`model`]: the model chosen as a whole: the candidates that stand out, each part of a
//!   family on its own, and pairs, judged by the evidence of both campaigns (the F-test and
//!   the held-out or cross-validated prediction, combined), by whether the gain matters and
//!   whether the values are physical; the simplest within one standard error of the best
//!   predicting is named. Its files: [`entry`] (one model, fitted and predicting), [`pool`]
//!   (the models tried beside the single candidates), [`gain`] (the rule a gain must meet:
//!   significant on both campaigns, not contradicted, better by a practical amount, physical
//!   values). [`settle`]: a family of the current model named whole keeps the parts the
//!   evidence needs, by the same rule.
//! - [`held_out_figures`]: one model's held-out figures, made once: its errors, the same
//!   with each setup's zero removed and in their own noise, their RMS, the noise's floors.
//! - [`held_out`]: the held-out judge: errors with each setup's zero removed, the model's
//!   floor (noise and the calibration's own uncertainty), the χ² test against it, the
//!   structure of the held-out residual; [`validation`]: the held-out data with their noise.
//! - [`structure`]: the three structure tests that rest on no noise level: a dictionary of
//!   smooth terms ([`sparse`]), a periodogram of each carrier's position ([`periodic`]),
//!   neighbours along each setup's path ([`neighbours`]).
//! - [`verdict`]: `missing_effect`, `unexplained_structure` (the calibration's residual or
//!   the held-out data's, with what it follows) or `nothing_missing` (only where the held-out
//!   data agree).
//! - [`held_out_poses`]: the judge's residual pose by pose (the JSON, the report's plots).
//! - [`coverage`]: the held-out campaign's covariates, their rates and its poses against
//!   the calibration's ranges (an extrapolation said beside the judge).
//! - [`figures`]: residual tables, maps and error vectors; [`types`]: the vocabulary;
//!   [`cross`]: prediction without held-out data, cross-validation by setup.

pub mod carried;
pub mod coverage;
pub mod cross;
pub mod current;
mod entry;
mod figures;
pub mod gain;
pub mod held_out;
pub mod held_out_figures;
pub mod held_out_poses;
mod model;
pub mod neighbours;
pub mod periodic;
mod pool;
mod rounds;
mod settle;
pub mod sparse;
mod structure;
mod trials;
pub mod types;
mod validation;
mod verdict;

pub use current::{calib_options, evaluate, Evaluated};
pub use held_out::judge_calibration;
pub use held_out_figures::{HeldOut, HeldOutErrors};
pub use rounds::{diagnose, diagnose_among};
pub use trials::SCREEN_P;
pub use types::{
    Baseline, Candidate, DiagnoseError, DiagnosisOptions, ErrorVector, EvidenceOf, Fit, GroupRms,
    HeldOutCheck, Judged, ModelDiagnosis, ModelTrial, NoiseReport, Noisier, Outcome, Prediction,
    ResidualPoint, RmsUnit, Skipped, Test, VerdictKind, NOISIER_THAN_RATED, NUMERICAL_RMS_MM,
    RELEVANT_FRACTION,
};
