//! Measurement noise of the instruments and encoders (spec "Workspace and measurement
//! campaigns"). One place: the twin draws noise from it and the calibration weights by it
//! (task-variable scaling, thesis eq. 3.21-3.22).

use crate::campaign::Instrument;
use nalgebra::{Matrix2, Vector2};

/// Position of the laser tracker in the machine frame, mm: in front of the machine on its
/// axis of symmetry, so the beam runs roughly along y and TCP distances are 2.2-4.2 m.
pub const TRACKER_POSITION: [f64; 2] = [0.0, -1500.0];
/// Laser tracker noise along the beam, mm.
pub const LT_ALONG_MM: f64 = 0.005;
/// Laser tracker noise across the beam: 18 µm + 3 µm per metre of distance, mm.
pub const LT_ACROSS_MM: f64 = 0.018;
pub const LT_ACROSS_PER_M_MM: f64 = 0.003;
/// Grid encoder (KGM 182), double ball-bar, laser interferometer: about 1 µm.
pub const KGM_MM: f64 = 0.001;
pub const DBB_MM: f64 = 0.001;
pub const LI_MM: f64 = 0.001;
/// Platform angle optics: about 1 µrad.
pub const PSI_RAD: f64 = 1e-6;
/// Actuator encoders (linear scales of the direct drives), mm. The spec gives none; a
/// linear scale of this class reads to a few tenths of a micrometre.
pub const ENCODER_MM: f64 = 0.0002;

/// Covariance (mm²) of a laser-tracker reading of the TCP at `tcp` (mm).
pub fn lt_covariance(tcp: Vector2<f64>) -> Matrix2<f64> {
    let beam = tcp - Vector2::from(TRACKER_POSITION);
    let dist_m = beam.norm() / 1000.0;
    let u = beam.normalize();
    let v = Vector2::new(-u.y, u.x);
    let across = LT_ACROSS_MM + LT_ACROSS_PER_M_MM * dist_m;
    u * u.transpose() * LT_ALONG_MM.powi(2) + v * v.transpose() * across.powi(2)
}

/// Covariance (mm²) of an (x, y) reading of a TCP-measuring instrument at `tcp`.
pub fn xy_covariance(instrument: Instrument, tcp: Vector2<f64>) -> Matrix2<f64> {
    match instrument {
        Instrument::Lt => lt_covariance(tcp),
        Instrument::Kgm => Matrix2::identity() * KGM_MM.powi(2),
        _ => Matrix2::identity() * LI_MM.powi(2),
    }
}

/// Standard deviation of a scalar reading: r of the ball-bar (mm), one LI coordinate (mm),
/// ψ (rad), a follower encoder (mm).
pub fn scalar_sigma(instrument: Instrument) -> f64 {
    match instrument {
        Instrument::Dbb | Instrument::Circle => DBB_MM,
        Instrument::LiX | Instrument::LiY => LI_MM,
        Instrument::LiPsi => PSI_RAD,
        Instrument::SelfCal | Instrument::None => ENCODER_MM,
        Instrument::Kgm => KGM_MM,
        Instrument::Lt => LT_ALONG_MM,
    }
}
