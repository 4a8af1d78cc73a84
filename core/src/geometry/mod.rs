//! Loop-closure geometry of the Scissors-Kinematics: igm, fgm of every viable subsystem, rgm.
//!
//! Every geometric model of the thesis is one square system. The configuration has seven
//! variables c = (x, y, ψ, q1, q2, q3, q4); the model imposes five equations: the loop
//! closures of rods 1-4 plus, for model 29, rod 5 or, for model 24, the perfect-parallel-holder
//! constraint ψ = γ2. Knowing two configuration variables fixes the other five:
//! - igm: (x, y) known,
//! - fgm of a non-redundant subsystem: two actuators known ((q1,q4), (q3,q4), (q2,q3), (q1,q2)),
//! - rgm: (q1, q4) known, (q2, q3) read off the same solution.
//!
//! The solve starts from the analytic model-24 answer (seed eq. 4.6 and annex A) and polishes
//! with Newton; its sensitivities to the parameters and to the known variables come from the
//! implicit function theorem, dc_u = −E_u⁻¹ (E_p dp + E_k dc_k), so calibration Jacobians are
//! analytic and exact (they are checked against finite differences in the tests).
//!
//! Files, one job each:
//! - `config.rs`: The configuration's seven variables, a solution, the solver's tolerances,
//!   its errors and the viable subsystems.
//! - `closure.rs`: The guides' frames, the joints and the loop-closure equations, with their
//!   derivatives in the configuration and the parameters.
//! - `igm.rs`: The inverse model: each rod by eq. 4.6, the closed-form model 24, and model
//!   29's platform angle by secant steps.
//! - `newton.rs`: Newton's polish of a start and the 5 x 5 LU with its conditioning check.
//! - `fgm.rs`: The forward model's analytic starts: two circles per known drive pair, and rod
//!   5's closure in model 29.
//! - `solve.rs`: The entry points: solve any subsystem from its start (igm, fgm, rgm).
//! - `sensitivity.rs`: The implicit-function sensitivities of a solution to the parameters
//!   and the known variables.
//! - `tests.rs`: the module's unit tests.

mod closure;
mod config;
mod fgm;
mod igm;
mod newton;
mod sensitivity;
mod solve;
#[cfg(test)]
mod tests;

pub use closure::{carrier_joint, closure, closure_params, guide_frame, platform_joint, Closure};
pub(crate) use closure::{frames, Frames};
pub use config::{
    q_var, Config, GeometryError, ParamJacobian, Solution, Subsystem, MAX_ITER, PSI, TOL_MM2, X, Y,
};
pub(crate) use igm::near;
pub use igm::rod_igm;
pub(crate) use sensitivity::sensitivity_rows_into;
pub use sensitivity::{sensitivity, sensitivity_into, Sensitivity};
pub use solve::{fgm, igm, rgm, solve};
pub(crate) use solve::{fgm29_from, fgm_with_frames};
