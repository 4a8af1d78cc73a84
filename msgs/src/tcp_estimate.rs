//! `rpkm_msgs/msg/TcpEstimate` (msgs/msg/TcpEstimate.msg).
//!
//! Wire compatibility: `outcome` and `reason` were appended after `converged`, the last field
//! before them. A CDR reader with the older definition decodes the fields it knows and stops
//! before the two extra bytes (the body is plain XCDR1, no member headers), so older peers
//! keep working; a reader of this definition needs both bytes, so it cannot read samples from
//! an older writer (which sends 2 bytes less). The ROS 2 type name is unchanged.

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
    /// `bool converged`: a plausible elastic equilibrium (false: the rigid fallback).
    pub converged: bool,
    /// `uint8 outcome`: how the estimate was obtained, one of `TcpEstimate::OUTCOME_*`.
    /// Appended after `converged` (see the module documentation).
    pub outcome: u8,
    /// `uint8 reason`: the check that rejected the elastic solve, one of
    /// `TcpEstimate::REASON_*` (the codes of `rpkm_core::elastic::plausibility::Reason`).
    pub reason: u8,
}

// outcome and reason fill the two bytes of padding after converged: the size is unchanged.
const _: () = assert!(core::mem::size_of::<TcpEstimate>() == 160);
const _: () = assert!(core::mem::align_of::<TcpEstimate>() == 8);

impl TcpEstimate {
    /// `uint8 MODEL_24=24`: 24 parameters, perfect parallel-holder.
    pub const MODEL_24: u8 = 24;
    /// `uint8 MODEL_29=29`: 29 parameters, psi from rods 4 and 5.
    pub const MODEL_29: u8 = 29;

    /// `uint8 OUTCOME_OK=0`: a plausible elastic equilibrium, warm-started (or cold when there
    /// was no previous one).
    pub const OUTCOME_OK: u8 = 0;
    /// `uint8 OUTCOME_WARM_REJECTED_COLD_OK=1`: the warm solve failed the check in `reason`;
    /// the cold solve passed and is the estimate.
    pub const OUTCOME_WARM_REJECTED_COLD_OK: u8 = 1;
    /// `uint8 OUTCOME_RIGID_FALLBACK=2`: no plausible elastic equilibrium (`reason` is the cold
    /// solve's); the pose is the rigid model of q1, q4, `converged` false, forces 0.
    pub const OUTCOME_RIGID_FALLBACK: u8 = 2;

    /// `uint8 REASON_NONE=0`: no check failed.
    pub const REASON_NONE: u8 = 0;
    /// `uint8 REASON_NOT_CONVERGED=1`: no finite elastic solution.
    pub const REASON_NOT_CONVERGED: u8 = 1;
    /// `uint8 REASON_LOOP_CLOSURE=2`: a rod length or carrier position disagrees.
    pub const REASON_LOOP_CLOSURE: u8 = 2;
    /// `uint8 REASON_FORCE_BALANCE=3`: the platform is not in balance.
    pub const REASON_FORCE_BALANCE: u8 = 3;
    /// `uint8 REASON_FORCE_LIMIT=4`: a force far beyond the drives'.
    pub const REASON_FORCE_LIMIT: u8 = 4;
    /// `uint8 REASON_PLATFORM_ANGLE=5`: ψ far from γ2.
    pub const REASON_PLATFORM_ANGLE: u8 = 5;
    /// `uint8 REASON_FAR_FROM_RIGID=6`: the TCP far from the rigid model.
    pub const REASON_FAR_FROM_RIGID: u8 = 6;
}

crate::ros_message!(
    TcpEstimate,
    "rpkm_msgs",
    "TcpEstimate",
    include_str!("../msg/TcpEstimate.msg"),
    [Time]
);
