//! The state's layout, the options of the filter, the step test and the tie test, and their
//! defaults.

use crate::calib::Prior;
use crate::noise::{DriveNoise, NoiseModel};
use crate::params::N_PARAMS;
use nalgebra::{SMatrix, SVector};

/// The state's units inside the filter: the tolerance prior (0.1 mm, 1 mrad) and 10 % of
/// the stiffness.
pub(super) fn scale() -> SVector<f64, N_STATE> {
    let prior = Prior::default();
    SVector::from_fn(|i, _| if i == STIFFNESS { 0.1 } else { prior.sigma(i) })
}

/// Unknowns: the 29 parameters, then the stiffness change.
pub const N_STATE: usize = N_PARAMS + 1;
/// Index of the stiffness change in the state.
pub const STIFFNESS: usize = N_PARAMS;
/// Gate of the normalised innovation of one sample (4 forces): χ²₄ quantile at 1 − 1e-6.
pub const GATE_CHI2_4: f64 = 33.4;

pub type Covariance = SMatrix<f64, N_STATE, N_STATE>;
pub(super) type Rows = SMatrix<f64, 4, N_STATE>;

/// Settings of the online estimator.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OnlineOptions {
    /// σ of a drive force reading, N.
    pub force_sigma_n: f64,
    /// σ of a drive's encoder, mm: the drives hold their commands, so an encoder's error
    /// moves the forces by the rods' stiffness ([`DriveNoise`]; the calibration's
    /// `drive_position` group).
    pub encoder_sigma_mm: f64,
    /// Random-walk rate of the lengths, mm per √h (thermal drift of a steel machine: about
    /// 11.5 µm per m and K).
    pub length_drift_mm_per_sqrt_h: f64,
    /// Random-walk rate of the angles, rad per √h.
    pub angle_drift_rad_per_sqrt_h: f64,
    /// Random-walk rate of the stiffness change, per √h.
    pub stiffness_drift_per_sqrt_h: f64,
    /// σ of the stiffness change at the start (0: held at the start value, the default).
    pub stiffness_sigma: f64,
    /// Gated samples in a row that make a step change.
    pub step_samples: usize,
    /// A step is named once its best parameter explains the held innovations this many
    /// times better (χ² reduction) than the next ([`StepChange::margin`]) ...
    pub step_margin: f64,
    /// ... or when this many samples are held, whatever the margin.
    pub step_max_samples: usize,
    /// A step named with its runner-up is told apart once the two estimates' predictions of
    /// the samples since differ by this much evidence (χ², −2 log-likelihood ratio) either
    /// way ([`TieEvidence`]).
    pub tie_evidence_chi2: f64,
    /// Which parameters a step change may be: a crash bends a rod, so the rod lengths by
    /// default (the forces cannot tell a rod's length from its joints' positions along it).
    pub step_candidates: StepCandidates,
}

/// The parameters a step change is attributed to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepCandidates {
    /// l1..l5.
    Rods,
    /// Every state (29 parameters and the stiffness).
    All,
}

impl StepCandidates {
    pub(super) fn states(self) -> Vec<usize> {
        match self {
            StepCandidates::Rods => crate::params::RODS.iter().map(|r| r.l).collect(),
            StepCandidates::All => (0..N_STATE).collect(),
        }
    }
}

impl OnlineOptions {
    /// The drive forces' noise the filter weighs a sample by.
    pub fn drives(&self) -> DriveNoise {
        DriveNoise {
            force_n: self.force_sigma_n,
            encoder_mm: self.encoder_sigma_mm,
        }
    }
}

impl Default for OnlineOptions {
    fn default() -> Self {
        OnlineOptions {
            force_sigma_n: 5.0,
            // the calibration's stated level
            encoder_sigma_mm: NoiseModel::default().drive_position_mm,
            length_drift_mm_per_sqrt_h: 0.05,
            angle_drift_rad_per_sqrt_h: 2e-5,
            stiffness_drift_per_sqrt_h: 0.0,
            // held: forces alone cannot tell it from the geometry (rpkm analyze
            // observability --method currents); an offline calibration of forces and
            // followers gives it
            stiffness_sigma: 1e-6,
            step_samples: 10,
            step_margin: 1.5,
            step_max_samples: 60,
            tie_evidence_chi2: TIE_EVIDENCE_CHI2,
            step_candidates: StepCandidates::Rods,
        }
    }
}

/// Evidence that tells a tie apart: a likelihood ratio of 10⁶ (2 ln 10⁶), the false-alarm
/// level of the gate.
pub const TIE_EVIDENCE_CHI2: f64 = 27.63;

/// Most poses of a motion that settles a tie (a minute of the cell's time at a few
/// seconds a pose).
pub const TIE_MOTION_POSES: usize = 12;
