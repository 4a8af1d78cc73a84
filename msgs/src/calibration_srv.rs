//! `rpkm_msgs/srv/LoadCalibration` and `rpkm_msgs/srv/SaveCalibration`
//! (msgs/srv/*.srv): the node services `~/load_calibration` and `~/save_calibration`.

use serde::{Deserialize, Serialize};

/// The request of both services: a calibration JSON path.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CalibrationFileRequest {
    /// `string path`.
    pub path: String,
}

/// The response of both services.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct CalibrationFileResponse {
    /// `bool success`.
    pub success: bool,
    /// `string message`: what was done, or why not.
    pub message: String,
}

crate::ros_message!(
    CalibrationFileRequest,
    "rpkm_msgs",
    "LoadCalibration_Request",
    "string path\n",
    []
);
crate::ros_message!(
    CalibrationFileResponse,
    "rpkm_msgs",
    "LoadCalibration_Response",
    "bool success\nstring message\n",
    []
);

/// The services' type names (`rpkm_msgs/srv/<name>`).
pub const LOAD_CALIBRATION: &str = "LoadCalibration";
/// See [`LOAD_CALIBRATION`].
pub const SAVE_CALIBRATION: &str = "SaveCalibration";
