//! `rpkm_msgs/msg/Parameters` (msgs/msg/Parameters.msg).

use serde::{Deserialize, Serialize};

/// Identified geometric parameter set of one model, with campaign statistics.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Parameters {
    /// `uint8 model`: 24 or 29.
    pub model: u8,
    /// `string[] names`: parameter names (`l1`, `xa1r`, `gamma1`, ...).
    pub names: Vec<String>,
    /// `float64[] values`: values in the order of `names` (m, rad).
    pub values: Vec<f64>,
    /// `float64[] sigmas`: standard deviations of `values` (m, rad).
    pub sigmas: Vec<f64>,
    /// `string[] active_effects`: active additional effects.
    pub active_effects: Vec<String>,
    /// `string[] effect_parameter_names`.
    pub effect_parameter_names: Vec<String>,
    /// `float64[] effect_parameter_values`: in the order of `effect_parameter_names` (SI).
    pub effect_parameter_values: Vec<f64>,
    /// `uint32 measurement_count`: measurements used in the calibration (1).
    pub measurement_count: u32,
    /// `float64 cal_rms`: RMS of the calibration residuals (m).
    pub cal_rms: f64,
    /// `float64 val_rms`: RMS of the validation residuals (m).
    pub val_rms: f64,
    /// `float64 max_abs_residual`: largest absolute calibration residual (m).
    pub max_abs_residual: f64,
    /// `float64 condition_number`: of the identification Jacobian (1).
    pub condition_number: f64,
}

crate::ros_message!(
    Parameters,
    "rpkm_msgs",
    "Parameters",
    include_str!("../msg/Parameters.msg"),
    []
);
