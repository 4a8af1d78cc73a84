//! The configuration's seven variables, a solution, the solver's tolerances, its errors and the
//! viable subsystems.

use crate::params::N_PARAMS;
use nalgebra::{SMatrix, SVector};

/// Configuration variable indexes.
pub const X: usize = 0;
pub const Y: usize = 1;
pub const PSI: usize = 2;
/// Index of actuator `i` (0..=3 for q1..q4) in the configuration.
pub const fn q_var(i: usize) -> usize {
    3 + i
}

/// Configuration (x, y, ψ, q1, q2, q3, q4), mm and rad.
pub type Config = SVector<f64, 7>;
/// Sensitivity of the configuration to the 29 parameters.
pub type ParamJacobian = SMatrix<f64, 7, N_PARAMS>;

/// Residual tolerance of the Newton solves on the loop closures |A−B|² − l², in mm²
/// (the thesis stops at |F| < 1e-8 mm²; that is 5e-12 mm on a 950 mm rod).
pub const TOL_MM2: f64 = 1e-8;
/// Iteration cap of the Newton solves (the thesis reports 4-5 iterations).
pub const MAX_ITER: usize = 20;
/// Below this ratio |det| / Π‖rows‖ the system counts as singular.
pub(super) const SINGULAR_RATIO: f64 = 1e-7;

/// A geometric solve that failed: typed, never a NaN.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeometryError {
    #[error("rod {rod} cannot reach its carrier guide at this pose (discriminant {discriminant:.3e} mm²)")]
    Unreachable { rod: usize, discriminant: f64 },
    #[error("rods {a} and {b} do not intersect for these actuator positions (circles {gap:.3e} mm apart)")]
    NoIntersection { a: usize, b: usize, gap: f64 },
    #[error("the subsystem {subsystem} is singular at this pose (conditioning ratio {ratio:.2e})")]
    Singular { subsystem: Subsystem, ratio: f64 },
    #[error("{what} did not converge in {iterations} iterations (residual {residual:.3e} mm²)")]
    NotConverged {
        what: &'static str,
        iterations: usize,
        residual: f64,
    },
    #[error("the solution leaves the assembly mode of rod {rod}")]
    AssemblyMode { rod: usize },
    #[error("non-finite input")]
    NonFinite,
}

/// A pair of known configuration variables: the inputs of a geometric model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Subsystem {
    /// (x, y) known: the inverse geometric model.
    Tcp,
    /// Two actuators known: a forward model of a non-redundant subsystem (0-based indexes, a < b).
    Actuators(usize, usize),
}

impl Subsystem {
    /// The non-redundant subsystem the thesis uses for fgm and rgm: (q1, q4).
    pub const NR: Subsystem = Subsystem::Actuators(0, 3);
    /// The viable forward subsystems ((q2,q4) and (q1,q3) are singular at x = 0).
    pub const VIABLE: [Subsystem; 4] = [
        Subsystem::Actuators(0, 3),
        Subsystem::Actuators(2, 3),
        Subsystem::Actuators(1, 2),
        Subsystem::Actuators(0, 1),
    ];

    pub(super) fn known(self) -> [usize; 2] {
        match self {
            Subsystem::Tcp => [X, Y],
            Subsystem::Actuators(a, b) => [q_var(a), q_var(b)],
        }
    }

    pub(super) fn unknown(self) -> [usize; 5] {
        let k = self.known();
        let mut out = [0; 5];
        let mut n = 0;
        for v in 0..7 {
            if !k.contains(&v) {
                out[n] = v;
                n += 1;
            }
        }
        out
    }
}

impl std::fmt::Display for Subsystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Subsystem::Tcp => write!(f, "(x, y)"),
            Subsystem::Actuators(a, b) => write!(f, "(q{}, q{})", a + 1, b + 1),
        }
    }
}

/// A solved configuration and how it was reached.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    pub c: Config,
    /// Newton iterations after the analytic start.
    pub iterations: usize,
    /// Largest closure residual at the end, mm².
    pub residual: f64,
}

impl Solution {
    pub fn x(&self) -> f64 {
        self.c[X]
    }
    pub fn y(&self) -> f64 {
        self.c[Y]
    }
    pub fn psi(&self) -> f64 {
        self.c[PSI]
    }
    /// Actuator positions q1..q4.
    pub fn q(&self) -> [f64; 4] {
        [self.c[3], self.c[4], self.c[5], self.c[6]]
    }
}
