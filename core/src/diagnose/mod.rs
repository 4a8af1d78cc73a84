//! Model discovery: where the model fails, which physical effect is missing, and what the
//! held-out error becomes once it is added. No step hinges on an assumed noise level.
//!
//! The stages, one folder or file each:
//!
//! - [`rounds`]: the flow. Every candidate at the stated noise first (which stand out), the
//!   current model on its own, then the candidates again under the noise estimated with
//!   those that stood out.
//! - [`current`]: the current model as every command evaluates it: its noise estimated from
//!   the campaign, a family named whole settled to the parts the data can tell apart, its
//!   held-out figures ([`evaluate`], which `rpkm calibrate`'s table of stages uses).
//! - [`search`]: the candidates tried and the model chosen as a whole ([`search::trials`],
//!   [`search::model`], [`search::entry`], [`search::pool`], [`search::gain`],
//!   [`search::settle`], [`search::cross`]).
//! - [`structure`]: the three structure tests that rest on no noise level: a dictionary of
//!   smooth terms ([`structure::sparse`]), a periodogram of each carrier's position
//!   ([`structure::periodic`]), neighbours along each setup's path
//!   ([`structure::neighbours`]); and what a lagging thermometer's noise leaves in a residual
//!   ([`structure::carried`]).
//! - [`held_out`]: the held-out judge: errors with each setup's zero removed, the model's
//!   floor (noise and the calibration's own uncertainty), the χ² test against it, the
//!   structure of the held-out residual; its figures made once per model
//!   ([`held_out::figures`]), the held-out data with their noise ([`held_out::validation`]),
//!   the residual pose by pose ([`held_out::poses`]: the JSON, the report's plots), the
//!   held-out campaign's covariates, their rates and its poses against the calibration's
//!   ranges ([`held_out::coverage`]: an extrapolation said beside the judge).
//! - [`verdict`]: `missing_effect`, `unexplained_structure` (the calibration's residual or
//!   the held-out data's, with what it follows) or `nothing_missing` (only where the held-out
//!   data agree).
//! - [`figures`]: residual tables, maps and error vectors; [`types`]: the vocabulary.

pub mod current;
mod figures;
pub mod held_out;
mod rounds;
pub mod search;
pub mod structure;
pub mod types;
mod verdict;

pub use current::{calib_options, evaluate, Evaluated};
pub use held_out::figures::{HeldOut, HeldOutErrors};
pub use held_out::judge_calibration;
pub use rounds::{diagnose, diagnose_among};
pub use search::trials::SCREEN_P;
pub use types::{
    Baseline, Candidate, DiagnoseError, DiagnosisOptions, ErrorVector, EvidenceOf, Fit, GroupRms,
    HeldOutCheck, Judged, ModelDiagnosis, ModelTrial, NoiseReport, Noisier, Outcome, Prediction,
    ResidualPoint, RmsUnit, Skipped, Test, Undecided, VerdictKind, NOISIER_THAN_RATED,
    NUMERICAL_RMS_MM, RELEVANT_FRACTION,
};
