//! What a report shows: the command, the campaign, the diagnoses before and after, the
//! models' table. The page (`mod.rs`) and its sections read it.

use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::ModelDiagnosis;

/// One model of the story: its name and how it fits.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ModelRow {
    pub model: String,
    pub cal_rms_um: f64,
    pub val_rms_um: Option<f64>,
    /// χ²/ν with the rows weighted by the table's one noise ([`ModelTable::chi2_under`]).
    pub chi2_per_dof: f64,
}

/// The models' table as a command made it: its rows, and the one noise their χ² are under
/// (each model under its own estimate would read about 1 on every row).
pub struct ModelTable {
    pub rows: Vec<ModelRow>,
    /// The noise, in words: "the stated noise", "the noise estimated with the last model".
    pub chi2_under: String,
}

/// What the report shows: the diagnosis of the current model and, when an effect was added,
/// the diagnosis with it ("after"), each with its residuals and error vectors.
pub struct Report<'a> {
    /// The command that made it (`rpkm diagnose`, `rpkm demo`, `rpkm calibrate`).
    pub command: &'a str,
    pub campaign: &'a Campaign,
    /// The held-out campaign (`--validate`), whose residuals the page plots pose by pose.
    pub validation: Option<&'a Campaign>,
    pub before: &'a ModelDiagnosis,
    pub after: Option<&'a ModelDiagnosis>,
    /// The models in the order they were fitted (the first is `before`'s).
    pub stages: Vec<ModelRow>,
    /// The one noise the stages' χ² are under, in words.
    pub chi2_under: String,
    /// The effects of an effects file: (name, its expressions as written).
    pub written: Vec<(String, String)>,
}
