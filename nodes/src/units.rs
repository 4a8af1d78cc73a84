//! Units between the core and the topics: the core works in mm, rad, N, s (the thesis's),
//! the ROS topics in SI (REP 103), a person reads µm, mrad and ms. The factors between them
//! live here; the message adapters (`campaign_bag`, the Parameters message of
//! `node::geometry`) and the nodes convert with these named functions, never with a bare
//! factor (tests/layers.rs holds it).

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

/// A length on a topic (m) in the core's mm.
pub fn mm_from_m(m: f64) -> f64 {
    m * MM_PER_M
}

/// A length in the core's mm as a topic carries it (m).
pub fn m_from_mm(mm: f64) -> f64 {
    mm / MM_PER_M
}

/// A length in µm (the diagnosis's RMS, a noise level) as a topic carries it (m).
pub fn m_from_um(um: f64) -> f64 {
    um * 1e-6
}

/// A length on a topic (m) in µm, as a person reads it.
pub fn um_from_m(m: f64) -> f64 {
    m * 1e6
}

/// An angle in rad in mrad, as a person reads it.
pub fn mrad_from_rad(rad: f64) -> f64 {
    rad * 1e3
}

/// A duration in ms (a parameter such as `busy_poll_ms`) in s.
pub fn seconds_from_ms(ms: f64) -> f64 {
    ms * 1e-3
}

/// A duration in s in ms, as a person reads it.
pub fn ms_from_seconds(s: f64) -> f64 {
    s * 1e3
}
