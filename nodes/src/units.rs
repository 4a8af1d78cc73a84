//! Units between the core and the topics: the core works in mm, rad, N, s (the thesis's),
//! the ROS topics in SI (REP 103). The one factor between them lives here; campaigns
//! (`campaign_bag`), streams and the nodes convert with it.

/// Millimetres per metre.
pub const MM_PER_M: f64 = 1000.0;

/// Micrometres per millimetre: tolerances, noise levels and drifts a person reads in µm.
pub const UM_PER_MM: f64 = 1000.0;

/// A length in µm (a parameter such as `online_drift_warn_um`) in the core's mm.
pub fn mm_from_um(um: f64) -> f64 {
    um / UM_PER_MM
}

/// A length in the core's mm in µm.
pub fn um_from_mm(mm: f64) -> f64 {
    mm * UM_PER_MM
}
