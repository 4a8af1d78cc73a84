//! `rpkm_msgs/msg/ActuatorState` (msgs/msg/ActuatorState.msg).

#[cfg(feature = "zero-copy")]
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// Capacity of [`ActuatorState::covariates`].
pub const MAX_COVARIATES: usize = 8;

/// State of the four linear drives q1..q4 at one control cycle. Fixed size, `#[repr(C)]`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "zero-copy", derive(ZeroCopySend))]
#[cfg_attr(
    feature = "zero-copy",
    type_name("rpkm_msgs::msg::dds_::ActuatorState_")
)]
#[repr(C)]
pub struct ActuatorState {
    /// `builtin_interfaces/Time stamp`: sampling time of the readings.
    pub stamp: Time,
    /// `uint64 seq`: sequence number, +1 per sample (1).
    pub seq: u64,
    /// `float64[4] position`: encoder positions q1..q4 (m).
    pub position: [f64; 4],
    /// `float64[4] force`: drive forces f1..f4 (N), positive towards larger q; 0 in follower
    /// mode; NaN where not measured.
    pub force: [f64; 4],
    /// `bool[4] follower`: drive i is in follower mode (controller off, encoder read only).
    pub follower: [bool; 4],
    /// `uint8 covariate_count`: number of valid entries of `covariates`, 0..=8 (1).
    pub covariate_count: u8,
    /// `float64[8] covariates`: covariates such as temperatures (degC); unused entries 0.
    pub covariates: [f64; MAX_COVARIATES],
}

const _: () = assert!(core::mem::size_of::<ActuatorState>() == 152);
const _: () = assert!(core::mem::align_of::<ActuatorState>() == 8);

crate::ros_message!(
    ActuatorState,
    "rpkm_msgs",
    "ActuatorState",
    include_str!("../msg/ActuatorState.msg"),
    [Time]
);

impl ActuatorState {
    /// The valid covariates (the first `covariate_count`, at most 8).
    pub fn covariates(&self) -> &[f64] {
        let n = usize::from(self.covariate_count).min(MAX_COVARIATES);
        &self.covariates[..n]
    }

    /// Sets the covariates; `None` if more than [`MAX_COVARIATES`] are given.
    pub fn set_covariates(&mut self, values: &[f64]) -> Option<()> {
        let count = u8::try_from(values.len())
            .ok()
            .filter(|_| values.len() <= MAX_COVARIATES)?;
        self.covariates = [0.0; MAX_COVARIATES];
        self.covariates[..values.len()].copy_from_slice(values);
        self.covariate_count = count;
        Some(())
    }
}
