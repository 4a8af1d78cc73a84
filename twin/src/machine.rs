//! The twin's machine: how it is configured, the state it keeps and how it fails. Every file
//! of the twin reads this one; it reads only the effects it is configured with.

use super::effects::{EffectKind, ALPHA_PER_K, REFERENCE_TEMP_C};
use nalgebra::Vector2;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use rpkm_core::campaign::Instrument;
use rpkm_core::elastic::{ElasticError, Stiffness};
use rpkm_core::geometry::GeometryError;
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::Params;
use std::collections::BTreeMap;

/// Time per pose, s.
pub const SECONDS_PER_POSE: f64 = 3.0;
/// Time between setups, s.
pub const SECONDS_BETWEEN_SETUPS: f64 = 120.0;
/// Noise of the machine temperature sensor, K.
pub const TEMP_SENSOR_K: f64 = 0.01;

/// Configuration of a twin.
#[derive(Clone, Debug, PartialEq)]
pub struct TwinConfig {
    /// Seed of every random draw (parameter errors, noise, alignment angles).
    pub seed: u64,
    /// Seed of the readings' noise alone, where it is not `seed`'s: the same machine
    /// measured again with other noise (a study's noise seeds).
    pub noise_seed: Option<u64>,
    /// Hidden effects and their magnitudes (units: [`EffectKind::unit`]).
    pub effects: Vec<(EffectKind, f64)>,
    /// σ of the true parameters' length errors, mm.
    pub length_sigma_mm: f64,
    /// σ of the true parameters' angle errors, rad.
    pub angle_sigma_rad: f64,
    /// Parameters the controller commands igm with (nominal by default).
    pub controller: Params,
    /// Stiffness of the true machine (used under `preload_elastic`).
    pub stiffness: Stiffness,
    /// What expands under the `thermal` effect, by how much, from which reference: the
    /// twin's own physics, which a test varies (a machine whose rods alone expand).
    pub thermal: ThermalPhysics,
    /// The noise of the twin's instruments and encoders (None: noiseless). Its own value:
    /// a test makes the machine noisier, or otherwise noisy, than the calibration assumes.
    pub noise: Option<NoiseModel>,
    /// What a relative instrument is zeroed on.
    pub reset: ResetReading,
    /// A periodic error of one carrier's scale (None: none).
    pub cyclic: Option<CyclicScale>,
    /// A relative instrument whose readings drift after its zero (None: none).
    pub drift: Option<ZeroDrift>,
}

/// A relative instrument whose readings drift after its zero (a tracker creeping as it warms,
/// an interferometer's air changing): every reading of a setup of `instrument` carries
/// `rate_per_s` times the time since the setup's reset pose, which read 0. The model has no
/// term for it; a return to the reset pose at the setup's end shows it
/// (`rpkm_core::returns`). A systematic error, not noise: a noiseless twin drifts too.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ZeroDrift {
    pub instrument: Instrument,
    /// Drift of the reading per second along x and y, mm/s; a single-coordinate instrument
    /// (ball-bar r, interferometer x or y, angle optics ψ in rad/s) drifts by the first.
    /// A tracker creeping 1 µm/min along y: `[0.0, 1e-3 / 60.0]`.
    pub rate_per_s: [f64; 2],
}

impl ZeroDrift {
    /// What a reading taken `seconds` after its setup's zero carries (x, y; a single
    /// coordinate in x), mm or rad.
    pub fn after(&self, seconds: f64) -> [f64; 2] {
        self.rate_per_s.map(|v| v * seconds)
    }
}

/// A periodic error of one carrier's scale (a linear scale's or an encoder's interpolation
/// error, a ball screw's pitch error): the carrier stands at its reading plus
/// `amplitude_mm` · sin(2π · reading / `pitch_mm` + `phase`). Not in the model's library: the
/// diagnosis must find it without a term made for it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CyclicScale {
    /// Carrier 0..=3 (q1..q4).
    pub carrier: usize,
    pub amplitude_mm: f64,
    pub pitch_mm: f64,
    /// rad.
    pub phase: f64,
}

impl CyclicScale {
    /// Carrier position minus reading at `reading` (mm).
    pub fn offset(&self, reading: f64) -> f64 {
        self.amplitude_mm * (std::f64::consts::TAU * reading / self.pitch_mm + self.phase).sin()
    }
}

/// What a relative instrument (tracker, grid encoder, interferometer) is zeroed on at its
/// setup's reset pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ResetReading {
    /// A reading with the instrument's noise, as a real instrument is: its error is in
    /// every reading of the setup.
    #[default]
    Noisy,
    /// The true position: readings independent of each other.
    Exact,
}

impl Default for TwinConfig {
    fn default() -> Self {
        TwinConfig {
            seed: 1,
            noise_seed: None,
            effects: Vec::new(),
            length_sigma_mm: 0.1,
            angle_sigma_rad: 2e-4,
            controller: Params::nominal(),
            stiffness: Stiffness::default(),
            noise: Some(NoiseModel::default()),
            thermal: ThermalPhysics::default(),
            reset: ResetReading::default(),
            cyclic: None,
            drift: None,
        }
    }
}

/// Expansion coefficients (1/K) of the parts of the twin under `thermal`, and the temperature
/// its true parameters hold at.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ThermalPhysics {
    /// Rod lengths l1..l5.
    pub rods_per_k: f64,
    /// Guide positions d1, d2 (the frame).
    pub frame_per_k: f64,
    /// Linear scales (carrier position per encoder reading).
    pub scales_per_k: f64,
    pub reference_c: f64,
    /// How fast each guide warms against the machine's mean (guide 1, guide 2): 1 and 1 a
    /// machine at one temperature; a guide by a motor warms faster. A guide, its scales and
    /// its half of the frame (d1 for guide 1, d2 for guide 2) expand with its own
    /// temperature; the rods with the mean.
    pub guide_rates: [f64; 2],
    /// Whether each guide carries a thermometer (`temp_guide1`, `temp_guide2` recorded beside
    /// `temp_machine`).
    pub guide_thermometers: bool,
    /// The thermometers' first-order time constant behind the temperature they stand for, s
    /// (0: they read it at once). They are at the machine's temperature at t = 0, where the
    /// swing starts from rest.
    #[serde(default)]
    pub thermometer_lag_s: f64,
}

impl Default for ThermalPhysics {
    /// An all-steel machine: everything expands at 11.5 ppm/K from 20 °C.
    fn default() -> Self {
        ThermalPhysics {
            rods_per_k: ALPHA_PER_K,
            frame_per_k: ALPHA_PER_K,
            scales_per_k: ALPHA_PER_K,
            reference_c: REFERENCE_TEMP_C,
            guide_rates: [1.0, 1.0],
            guide_thermometers: false,
            thermometer_lag_s: 0.0,
        }
    }
}

/// A twin that could not be built or could not drive a pose.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TwinError {
    #[error("effect {0} given twice")]
    DuplicateEffect(EffectKind),
    #[error("effect {effect}: magnitude {magnitude} is not a finite number{extra}")]
    BadMagnitude {
        effect: EffectKind,
        magnitude: f64,
        extra: &'static str,
    },
    #[error("setup {setup}, target ({x}, {y}) mm: controller igm: {source}")]
    Controller {
        setup: String,
        x: f64,
        y: f64,
        source: GeometryError,
    },
    #[error("setup {setup}, target ({x}, {y}) mm: true machine: {source}")]
    Machine {
        setup: String,
        x: f64,
        y: f64,
        source: GeometryError,
    },
    #[error("setup {setup}, target ({x}, {y}) mm: elastic model: {source}")]
    Elastic {
        setup: String,
        x: f64,
        y: f64,
        source: ElasticError,
    },
    #[error("setup {setup}: followers `{follower}`: the twin drives q2, q3 as followers (`23`) or all four active (empty)")]
    DriveMode { setup: String, follower: String },
    #[error("drift of {instrument}: {why}")]
    BadDrift {
        instrument: Instrument,
        why: &'static str,
    },
    #[error("setup {setup}: pose before its reset pose")]
    NoReset { setup: String },
    #[error("unknown campaign {0:?}, expected lt, kgm, dbb, li_x, li_y, li_psi, self, circle or validation")]
    UnknownCampaign(String),
}

/// The true state of the machine at one pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MachineState {
    /// TCP (mm) and platform angle (rad).
    pub tcp: Vector2<f64>,
    pub psi: f64,
    /// Encoder readings q1..q4 (without noise), mm.
    pub q: [f64; 4],
    /// Drive forces, N.
    pub f: [f64; 4],
    /// Followers.
    pub follower: [bool; 4],
}

/// The digital twin.
#[derive(Clone, Debug)]
pub struct Twin {
    pub(super) config: TwinConfig,
    pub(super) truth_params: Params,
    pub(super) rng: StdRng,
    /// The drive forces' noise: its own stream, so that the other readings draw the same
    /// numbers whether forces are recorded or not.
    pub(super) force_rng: StdRng,
    /// The readings the relative setups are zeroed on: their own stream, so that every other
    /// draw is the same whether resets are noisy or exact.
    pub(super) reset_rng: StdRng,
    /// The guides' thermometers: their own stream, so that every other draw is the same
    /// whether they are recorded or not.
    pub(super) guide_rng: StdRng,
    pub(super) t: f64,
    pub(super) alignment: BTreeMap<String, f64>,
}

pub(super) fn gauss(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}
