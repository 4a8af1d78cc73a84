//! The spring (lumped) elasto-geometric forward model: rods as axial springs, optional
//! carrier compliance along the guides, drives that hold their positions exactly.
//!
//! Unknowns z = (x, y, ψ, s1, s2, s3, s4): the platform pose and the four carrier positions
//! along their guides (same coordinate as the actuator positions q). The potential energy is
//!
//! V(z) = Σ_rods ½ k_i (|A_i − B_i(s)| − l_i)² + Σ_{active, compliant} ½ c_j (s_j − q_j)²
//!
//! and static equilibrium is ∇V = 0, except for an active drive with a rigid carrier, whose
//! equation is s_j = q_j (integral action: the encoder reads exactly its command). A drive in
//! follower mode exerts no force; its carrier slides freely and s_j is solved for. Newton with
//! the analytic Hessian (tangent stiffness, geometric-stiffness terms included) converges
//! quadratically from the rigid forward model of a pair of active drives.
//!
//! Files, one job each:
//! - `equilibrium.rs`: The model's constants and tolerances, the rods' stiffness, the drives'
//!   modes, an equilibrium and its errors.
//! - `energy.rs`: The potential energy's gradient and Hessian (tangent stiffness, geometric
//!   terms included) at a state z.
//! - `solve.rs`: The equilibrium's Newton: its rigid or warm start, the step through the free
//!   unknowns, the result checked.
//! - `sensitivity.rs`: The platform's balance and the equilibrium's sensitivities to the
//!   parameters.
//! - `tests.rs`: the module's unit tests.

mod energy;
mod equilibrium;
mod sensitivity;
mod solve;
#[cfg(test)]
mod tests;

pub use equilibrium::{
    ElasticError, Equilibrium, Followers, Stiffness, ALL_ACTIVE, DEFAULT_ROD_STIFFNESS_N_PER_MM,
    FOLLOWERS_23, MAX_ITER, NOMINAL_DRIVE_FORCE_N, STEP_TOL,
};
pub(super) use sensitivity::lengths_and_balance;
pub use sensitivity::{platform_balance, sensitivity, ElasticSensitivity};
pub use solve::fegm_unchecked;
pub(super) use solve::{rigid_start, solve_from, warm_start, Solved};
