//! `rpkm_msgs/msg/DiagnosisCandidate` (msgs/msg/DiagnosisCandidate.msg).

use serde::{Deserialize, Serialize};

/// One candidate effect tested by the diagnosis.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct DiagnosisCandidate {
    /// `string effect`: effect name.
    pub effect: String,
    /// `bool significant`: the effect reduces the validation residuals significantly.
    pub significant: bool,
    /// `float64 explained_fraction`: fraction of residual variance explained, 0..1.
    pub explained_fraction: f64,
    /// `float64 val_rms_before`: validation RMS without the effect (m).
    pub val_rms_before: f64,
    /// `float64 val_rms_after`: validation RMS with the effect (m).
    pub val_rms_after: f64,
}

crate::ros_message!(
    DiagnosisCandidate,
    "rpkm_msgs",
    "DiagnosisCandidate",
    include_str!("../msg/DiagnosisCandidate.msg"),
    []
);
