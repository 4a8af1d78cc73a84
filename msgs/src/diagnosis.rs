//! `rpkm_msgs/msg/Diagnosis` (msgs/msg/Diagnosis.msg).

use serde::{Deserialize, Serialize};

use crate::diagnosis_candidate::DiagnosisCandidate;

/// Result of the model diagnosis.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Diagnosis {
    /// `string missing_effect`: the missing effect; empty if none.
    pub missing_effect: String,
    /// `DiagnosisCandidate[] candidates`: every tested candidate.
    pub candidates: Vec<DiagnosisCandidate>,
    /// `float64 baseline_cal_rms`: calibration RMS of the baseline model (m).
    pub baseline_cal_rms: f64,
    /// `float64 baseline_val_rms`: validation RMS of the baseline model (m).
    pub baseline_val_rms: f64,
    /// `float64 noise_floor`: noise floor of the measurements (m).
    pub noise_floor: f64,
    /// `string verdict_kind`: nothing_missing, missing_effect or unexplained_structure.
    pub verdict_kind: String,
    /// `string verdict`: the verdict in words.
    pub verdict: String,
    /// `string[] missing_effects`: the model named, whole (empty: none).
    pub missing_effects: Vec<String>,
    /// `string[] model_effects`: the effects of the model diagnosed, as fitted.
    pub model_effects: Vec<String>,
    /// `float64 baseline_val_rms_relative`: held-out RMS, each setup's zero removed (m).
    pub baseline_val_rms_relative: f64,
    /// `float64 floor_relative`: the model's floor there (m).
    pub floor_relative: f64,
    /// `bool held_out_agrees`: the held-out data agree with the model.
    pub held_out_agrees: bool,
}

impl Diagnosis {
    /// The missing effect, `None` if the field is empty.
    pub fn missing_effect(&self) -> Option<&str> {
        (!self.missing_effect.is_empty()).then_some(self.missing_effect.as_str())
    }
}

crate::ros_message!(
    Diagnosis,
    "rpkm_msgs",
    "Diagnosis",
    include_str!("../msg/Diagnosis.msg"),
    [DiagnosisCandidate]
);
