//! `rpkm_msgs/msg/PreloadStatus` (msgs/msg/PreloadStatus.msg).

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// Internal preload monitor output.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct PreloadStatus {
    /// `builtin_interfaces/Time stamp`: stamp of the ActuatorState evaluated.
    pub stamp: Time,
    /// `float64[4] measured_current`: measured redundancy currents (%).
    pub measured_current: [f64; 4],
    /// `float64[4] predicted_current`: predicted redundancy currents (%).
    pub predicted_current: [f64; 4],
    /// `float64[4] deviation`: measured - predicted (%).
    pub deviation: [f64; 4],
    /// `float64 dq2`: follower-mode difference of q2, model - measured (m); NaN (not
    /// measured) unless q2 and q3 both follow.
    pub dq2: f64,
    /// `float64 dq3`: follower-mode difference of q3, model - measured (m); NaN (not
    /// measured) unless q2 and q3 both follow.
    pub dq3: f64,
    /// `uint8 level`: [`PreloadStatus::OK`], [`PreloadStatus::WARN`] or [`PreloadStatus::ERROR`].
    pub level: u8,
}

/// The levels of [`PreloadStatus::level`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(u8)]
pub enum PreloadLevel {
    /// `OK=0`.
    Ok = 0,
    /// `WARN=1`.
    Warn = 1,
    /// `ERROR=2`.
    Error = 2,
}

impl PreloadStatus {
    /// `uint8 OK=0`.
    pub const OK: u8 = 0;
    /// `uint8 WARN=1`.
    pub const WARN: u8 = 1;
    /// `uint8 ERROR=2`.
    pub const ERROR: u8 = 2;

    /// The level, `None` for a value outside the constants.
    pub fn level(&self) -> Option<PreloadLevel> {
        match self.level {
            0 => Some(PreloadLevel::Ok),
            1 => Some(PreloadLevel::Warn),
            2 => Some(PreloadLevel::Error),
            _ => None,
        }
    }
}

crate::ros_message!(
    PreloadStatus,
    "rpkm_msgs",
    "PreloadStatus",
    include_str!("../msg/PreloadStatus.msg"),
    [Time]
);
