//! What a report shows: the command, the campaign, the diagnoses before and after, the
//! models' table. The page (`mod.rs`) and its sections read it.

use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::Diagnosis;

/// One model of the story: its name and how it fits.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Stage {
    pub model: String,
    pub cal_rms_um: f64,
    pub val_rms_um: Option<f64>,
    pub chi2_per_dof: f64,
}

/// What the report shows: the diagnosis of the current model and, when an effect was added,
/// the diagnosis with it ("after"), each with its residuals and error vectors.
pub struct Report<'a> {
    /// The command that made it (`rpkm diagnose`, `rpkm demo`, `rpkm calibrate`).
    pub command: &'a str,
    pub campaign: &'a Campaign,
    pub before: &'a Diagnosis,
    pub after: Option<&'a Diagnosis>,
    /// The models in the order they were fitted (the first is `before`'s).
    pub stages: Vec<Stage>,
    /// The effects of an effects file: (name, its expressions as written).
    pub written: Vec<(String, String)>,
}
