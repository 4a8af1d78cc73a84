//! `rpkm_msgs/msg/TcpMeasurement` (msgs/msg/TcpMeasurement.msg).

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// One external TCP measurement by a metrology instrument.
#[expect(
    clippy::struct_excessive_bools,
    reason = "the .msg's validity flags, one per measured value, as ROS 2 defines the type"
)]
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TcpMeasurement {
    /// `builtin_interfaces/Time stamp`: time of the pose.
    pub stamp: Time,
    /// `string setup`: setup id; relative measurements share their setup's reset pose.
    pub setup: String,
    /// `uint8 instrument`: one of the `TcpMeasurement::LT..NONE` constants (see [`InstrumentId`]).
    pub instrument: u8,
    /// `bool reset`: reset pose of the setup (measured values 0).
    pub reset: bool,
    /// `float64 x`: x relative to the reset pose (m).
    pub x: f64,
    /// `bool x_valid`.
    pub x_valid: bool,
    /// `float64 y`: y relative to the reset pose (m).
    pub y: f64,
    /// `bool y_valid`.
    pub y_valid: bool,
    /// `float64 r`: ball-bar distance from the pivot (m).
    pub r: f64,
    /// `bool r_valid`.
    pub r_valid: bool,
    /// `float64 psi`: platform angle relative to the reset pose (rad).
    pub psi: f64,
    /// `bool psi_valid`.
    pub psi_valid: bool,
    /// `float64 sigma`: standard deviation of the noise (m; rad for LI_PSI).
    pub sigma: f64,
}

/// The metrology instruments, with their wire values (`uint8` constants of the `.msg`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum InstrumentId {
    /// `LT=0`: laser tracker.
    Lt = 0,
    /// `KGM=1`: grid encoder.
    Kgm = 1,
    /// `DBB=2`: double ball-bar.
    Dbb = 2,
    /// `LI_X=3`: laser interferometer along x.
    LiX = 3,
    /// `LI_Y=4`: laser interferometer along y.
    LiY = 4,
    /// `LI_PSI=5`: laser interferometer angle optics.
    LiPsi = 5,
    /// `SELF=6`: self-calibration.
    SelfCal = 6,
    /// `CIRCLE=7`: circular test.
    Circle = 7,
    /// `NONE=8`: no external measurement.
    None = 8,
}

/// A `uint8 instrument` value outside the `.msg` constants.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("unknown instrument id {0} (expected 0..=8)")]
pub struct UnknownInstrument(pub u8);

impl TryFrom<u8> for InstrumentId {
    type Error = UnknownInstrument;
    fn try_from(v: u8) -> Result<Self, Self::Error> {
        Ok(match v {
            0 => Self::Lt,
            1 => Self::Kgm,
            2 => Self::Dbb,
            3 => Self::LiX,
            4 => Self::LiY,
            5 => Self::LiPsi,
            6 => Self::SelfCal,
            7 => Self::Circle,
            8 => Self::None,
            other => return Err(UnknownInstrument(other)),
        })
    }
}

impl InstrumentId {
    /// The campaign CSV spelling (`lt`, `kgm`, ...).
    pub fn csv_name(self) -> &'static str {
        match self {
            Self::Lt => "lt",
            Self::Kgm => "kgm",
            Self::Dbb => "dbb",
            Self::LiX => "li_x",
            Self::LiY => "li_y",
            Self::LiPsi => "li_psi",
            Self::SelfCal => "self",
            Self::Circle => "circle",
            Self::None => "none",
        }
    }
}

impl TcpMeasurement {
    /// `uint8 LT=0`.
    pub const LT: u8 = 0;
    /// `uint8 KGM=1`.
    pub const KGM: u8 = 1;
    /// `uint8 DBB=2`.
    pub const DBB: u8 = 2;
    /// `uint8 LI_X=3`.
    pub const LI_X: u8 = 3;
    /// `uint8 LI_Y=4`.
    pub const LI_Y: u8 = 4;
    /// `uint8 LI_PSI=5`.
    pub const LI_PSI: u8 = 5;
    /// `uint8 SELF=6`.
    pub const SELF: u8 = 6;
    /// `uint8 CIRCLE=7`.
    pub const CIRCLE: u8 = 7;
    /// `uint8 NONE=8`.
    pub const NONE: u8 = 8;

    /// The instrument, or an error for a value outside the constants.
    pub fn instrument(&self) -> Result<InstrumentId, UnknownInstrument> {
        InstrumentId::try_from(self.instrument)
    }
}

crate::ros_message!(
    TcpMeasurement,
    "rpkm_msgs",
    "TcpMeasurement",
    include_str!("../msg/TcpMeasurement.msg"),
    [Time]
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instrument_ids_match_constants() {
        for v in 0..=8u8 {
            let i = InstrumentId::try_from(v).expect("valid id");
            assert_eq!(i as u8, v);
        }
        assert_eq!(InstrumentId::try_from(9), Err(UnknownInstrument(9)));
        assert_eq!(InstrumentId::LiPsi as u8, TcpMeasurement::LI_PSI);
        assert_eq!(InstrumentId::None as u8, TcpMeasurement::NONE);
    }
}
