//! `rpkm_msgs/msg/TcpEstimate` (msgs/msg/TcpEstimate.msg).

#[cfg(feature = "zero-copy")]
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// Forward-model answer to one [`crate::ActuatorState`]. Fixed size, `#[repr(C)]`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "zero-copy", derive(ZeroCopySend))]
#[cfg_attr(feature = "zero-copy", type_name("rpkm_msgs::msg::dds_::TcpEstimate_"))]
#[repr(C)]
pub struct TcpEstimate {
    /// `builtin_interfaces/Time stamp`: stamp of the ActuatorState answered.
    pub stamp: Time,
    /// `uint64 seq`: seq of the ActuatorState answered (1).
    pub seq: u64,
    /// `float64 x`: TCP x (m).
    pub x: f64,
    /// `float64 y`: TCP y (m).
    pub y: f64,
    /// `float64 psi`: platform angle (rad).
    pub psi: f64,
    /// `float64[5] loop_residuals`: |A_i - B_i| - l_i of rods 1..5 (m); rod 5 is 0 for model 24.
    pub loop_residuals: [f64; 5],
    /// `float64[5] rod_forces`: rod forces 1..5 (N), positive in tension.
    pub rod_forces: [f64; 5],
    /// `float64[4] drive_forces`: predicted drive forces f1..f4 (N), positive towards larger q.
    pub drive_forces: [f64; 4],
    /// `uint32 iterations`: solver iterations used (1).
    pub iterations: u32,
    /// `uint8 model`: [`TcpEstimate::MODEL_24`] or [`TcpEstimate::MODEL_29`].
    pub model: u8,
    /// `bool converged`: the solver converged within its tolerance.
    pub converged: bool,
}

const _: () = assert!(core::mem::size_of::<TcpEstimate>() == 160);
const _: () = assert!(core::mem::align_of::<TcpEstimate>() == 8);

impl TcpEstimate {
    /// `uint8 MODEL_24=24`: 24 parameters, perfect parallel-holder.
    pub const MODEL_24: u8 = 24;
    /// `uint8 MODEL_29=29`: 29 parameters, psi from rods 4 and 5.
    pub const MODEL_29: u8 = 29;
}

crate::ros_message!(
    TcpEstimate,
    "rpkm_msgs",
    "TcpEstimate",
    include_str!("../msg/TcpEstimate.msg"),
    [Time]
);
