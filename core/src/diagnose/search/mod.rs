//! The search: each effect of the library (and the user's written ones) tried beside the
//! current model, and the model chosen as a whole.
//!
//! - [`trials`]: each effect added and fitted, screened by one Gauss-Newton step, compared by
//!   the nested F-test F = (Δχ²/k) / (χ²₁/ν₁), free of the noise's absolute level.
//! - [`model`]: the model chosen as a whole: the candidates that stand out, each part of a
//!   family on its own, and pairs, judged by the evidence of both campaigns (the F-test and
//!   the held-out or cross-validated prediction, combined), by whether the gain matters and
//!   whether the values are physical; the simplest within one standard error of the best
//!   predicting is named. Its files: [`entry`] (one model, fitted and predicting), [`pool`]
//!   (the models tried beside the single candidates), [`gain`] (the rule a gain must meet:
//!   significant on both campaigns, not contradicted, better by a practical amount, physical
//!   values).
//! - [`settle`]: a family of the current model named whole keeps the parts the evidence
//!   needs, by the same rule, and only parts of physical value.
//! - [`cross`]: prediction without held-out data, cross-validation by setup.

pub mod cross;
pub(in crate::diagnose) mod entry;
pub mod gain;
pub(in crate::diagnose) mod model;
pub(in crate::diagnose) mod pool;
pub(in crate::diagnose) mod settle;
pub(in crate::diagnose) mod trials;
