//! Units, named once for the whole workspace: the core works in mm, rad, N, s (the thesis's),
//! the ROS topics in SI (REP 103), a person reads µm, mrad, ms and ppm. The factors between
//! them live here and nowhere else; the core, the twin, the message adapters of the nodes
//! (`rpkm_nodes::units`, which re-exports this module) and the text the command line writes
//! convert with these named functions, never with a bare factor (tests/layers.rs holds it).
//!
//! Each function keeps the one floating-point operation its callers used before it existed
//! (`x * 1e-3` and `x / 1000.0` round differently): a function that multiplies says so in
//! its body, one that divides likewise, so that moving a factor here changes no figure.

/// Millimetres per metre.
pub const MM_PER_M: f64 = 1000.0;

/// Micrometres per millimetre: tolerances, noise levels and drifts a person reads in µm.
pub const UM_PER_MM: f64 = 1000.0;

/// Radians per milliradian: the derivative of an angle given in mrad (a vector scales by it
/// where a function of one number cannot be called).
pub const RAD_PER_MRAD: f64 = 1e-3;

/// A length in µm (a parameter such as `online_drift_warn_um`) in the core's mm.
pub fn mm_from_um(um: f64) -> f64 {
    um / UM_PER_MM
}

/// A length in the core's mm in µm, as a person reads it.
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

/// An angle a person gives in mrad (a tolerance, a misalignment) in the core's rad.
pub fn rad_from_mrad(mrad: f64) -> f64 {
    mrad * RAD_PER_MRAD
}

/// A relative size in ppm (a scale error, an expansion per K) as a fraction.
pub fn fraction_from_ppm(ppm: f64) -> f64 {
    ppm * 1e-6
}

/// A duration in ms (a parameter such as `busy_poll_ms`) in s.
pub fn seconds_from_ms(ms: f64) -> f64 {
    ms * 1e-3
}

/// A duration in s in ms, as a person reads it.
pub fn ms_from_seconds(s: f64) -> f64 {
    s * 1e3
}

/// A duration in s in µs, as a person reads a time per pose.
pub fn us_from_seconds(s: f64) -> f64 {
    s * 1e6
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each conversion is the operation it replaced, to the bit: the factor the callers wrote
    /// before (`* 1e3`, `/ 1000.0`, `* 1e-6`, ...) on values whose products round.
    #[test]
    fn each_conversion_is_the_operation_it_replaced() {
        for x in [0.1, 0.9, 1.0 / 3.0, 17.123_456_789, -2.5e-7, 1234.5678] {
            assert_eq!(um_from_mm(x).to_bits(), (x * 1e3).to_bits());
            assert_eq!(mm_from_um(x).to_bits(), (x / 1000.0).to_bits());
            assert_eq!(mm_from_m(x).to_bits(), (x * 1000.0).to_bits());
            assert_eq!(m_from_mm(x).to_bits(), (x / 1000.0).to_bits());
            assert_eq!(m_from_um(x).to_bits(), (x * 1e-6).to_bits());
            assert_eq!(um_from_m(x).to_bits(), (x * 1e6).to_bits());
            assert_eq!(mrad_from_rad(x).to_bits(), (x * 1e3).to_bits());
            assert_eq!(rad_from_mrad(x).to_bits(), (x * 1e-3).to_bits());
            assert_eq!(fraction_from_ppm(x).to_bits(), (x * 1e-6).to_bits());
            assert_eq!(seconds_from_ms(x).to_bits(), (x * 1e-3).to_bits());
            assert_eq!(ms_from_seconds(x).to_bits(), (x * 1e3).to_bits());
            assert_eq!(us_from_seconds(x).to_bits(), (x * 1e6).to_bits());
        }
        // the two spellings this module keeps apart do round differently
        assert_ne!((0.9f64 / 1000.0).to_bits(), (0.9f64 * 1e-3).to_bits());
    }
}
