//! The model's constants and tolerances, the rods' stiffness, the drives' modes, an equilibrium
//! and its errors.

use crate::elastic::limits::Violation;
use crate::geometry;
use nalgebra::SVector;

/// Nominal drive force: 100 % redundancy current, N.
pub const NOMINAL_DRIVE_FORCE_N: f64 = 8600.0;
/// Newton stops after a step whose largest component falls below this, mm (or rad): with
/// quadratic convergence the error left is of the order of its square (< 1e-12 mm).
pub const STEP_TOL: f64 = 1e-7;
/// Iteration cap of the equilibrium Newton.
pub const MAX_ITER: usize = 30;
/// Newton also stops after a step s_k that the quadratic convergence of the two last steps
/// puts this close to the root, mm: the next step would be about s_k·(s_k/s_(k−1))². From a
/// warm start the steps run 0.3 mm, 4e-5 mm, 6e-13 mm: the third only confirmed the second,
/// and its 6e-13 mm is round-off on coordinates of 10³ mm. It is taken only after a
/// contraction by [`CONTRACTION`] at least, where the convergence is quadratic.
const PREDICTED_TOL: f64 = 1e-11;
/// The contraction of the last step against the one before that the prediction of
/// [`PREDICTED_TOL`] needs.
const CONTRACTION: f64 = 1e-3;

/// Whether Newton may stop after `step`, with `previous` the step before it: below
/// [`STEP_TOL`], or quadratically converging to within [`PREDICTED_TOL`]. The first step
/// has no previous one (infinite): only [`STEP_TOL`] stops it.
pub(super) fn converged(step: f64, previous: f64) -> bool {
    step < STEP_TOL
        || (previous.is_finite()
            && step <= CONTRACTION * previous
            && step * (step / previous).powi(2) < PREDICTED_TOL)
}

/// Default effective axial stiffness of each rod, N/mm (rod, its two joints and the carrier in
/// series). Chosen so that an incompatibility of 0.4 mm on one redundant drive (q3 offset by
/// 0.4 mm at the workspace centre, nominal parameters, rigid carriers) drives the most loaded
/// drive to about 100 % redundancy current, as the thesis reports (section 4.4): the model is
/// linear in the stiffness for small incompatibilities, so the value is the one that gives
/// 8,600 N there (see `core/tests/it/elastic_spring.rs::default_stiffness_gives_100_percent_for_0_4_mm`).
pub const DEFAULT_ROD_STIFFNESS_N_PER_MM: f64 = 97_700.0;

/// Stiffness of the spring model.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stiffness {
    /// Effective axial stiffness of rods 1..=5, N/mm.
    pub rod: [f64; 5],
    /// Stiffness of carriers 1..=4 along their guides (drive, ball screw/linear motor
    /// servo-stiffness and carrier in series), N/mm; `None` = rigid (the carrier sits exactly
    /// at its commanded position).
    pub carrier: [Option<f64>; 4],
}

impl Default for Stiffness {
    fn default() -> Self {
        Stiffness {
            rod: [DEFAULT_ROD_STIFFNESS_N_PER_MM; 5],
            carrier: [None; 4],
        }
    }
}

impl Stiffness {
    /// Every stiffness multiplied by `factor` (a compliance study: `factor` < 1 is softer).
    #[must_use]
    pub fn scaled(mut self, factor: f64) -> Self {
        for k in &mut self.rod {
            *k *= factor;
        }
        for c in self.carrier.iter_mut().flatten() {
            *c *= factor;
        }
        self
    }
}

/// Which drives are in follower mode (controller off, carrier free): `follower[i]` for q(i+1).
pub type Followers = [bool; 4];
/// All four drives position-controlled.
pub const ALL_ACTIVE: Followers = [false; 4];
/// q2, q3 followers (compatibility test, self-calibration).
pub const FOLLOWERS_23: Followers = [false, true, true, false];

/// An elasto-geometric solve that failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ElasticError {
    #[error("no pair of active drives among the viable subsystems: the platform is not held")]
    NotHeld,
    #[error("rigid start failed: {0}")]
    Start(#[from] geometry::GeometryError),
    #[error("equilibrium did not converge in {iterations} iterations (last step {step:.3e}, gradient {gradient:.3e} N)")]
    NotConverged {
        iterations: usize,
        step: f64,
        gradient: f64,
    },
    #[error("singular tangent stiffness at iteration {iteration}")]
    Singular { iteration: usize },
    #[error("non-finite input or state")]
    NonFinite,
    #[error("a rod length collapsed to zero")]
    Degenerate,
    #[error("implausible equilibrium: {0}")]
    Implausible(Violation),
}

/// Static equilibrium of the mechanism.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Equilibrium {
    /// Platform pose: TCP x, y (mm), angle ψ (rad).
    pub x: f64,
    pub y: f64,
    pub psi: f64,
    /// Carrier positions along their guides, mm (the commanded q for rigid active drives; the
    /// free position for followers).
    pub carrier: [f64; 4],
    /// Axial force of rods 1..=5, N, positive in tension.
    pub rod_force: [f64; 5],
    /// Drive forces f1..f4, N, positive when the drive pushes its carrier towards larger q; 0
    /// for a follower.
    pub drive_force: [f64; 4],
    /// Newton iterations.
    pub iterations: usize,
}

impl Equilibrium {
    /// Redundancy currents, % of the nominal 8,600 N, signed like the drive forces.
    pub fn current(&self) -> [f64; 4] {
        self.drive_force.map(|f| f / NOMINAL_DRIVE_FORCE_N * 100.0)
    }
    /// Largest |current| over the drives, %.
    pub fn max_current(&self) -> f64 {
        self.current().iter().fold(0.0, |m, c| m.max(c.abs()))
    }
    /// The unknown vector z = (x, y, ψ, s1..s4).
    pub fn z(&self) -> SVector<f64, 7> {
        SVector::<f64, 7>::from([
            self.x,
            self.y,
            self.psi,
            self.carrier[0],
            self.carrier[1],
            self.carrier[2],
            self.carrier[3],
        ])
    }
}
