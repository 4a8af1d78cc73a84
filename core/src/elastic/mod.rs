//! Elasto-geometric forward models of the redundantly actuated Scissors-Kinematics (thesis
//! chapter 5): the TCP pose and internal forces of a position-controlled redundant mechanism
//! from all four actuator positions, the geometric parameters and the stiffness.
//!
//! - [`spring`]: the lumped model (rods as axial springs, optional carrier compliance), the
//!   servo-rate fegm with analytic tangent stiffness and sensitivities;
//! - [`preload`]: the compatibility test (seed 4.4), predicted redundancy current, and the
//!   thesis's "first approach" (offsets on q2, q3 that create a requested preload, and the TCP
//!   displacement they cause);
//! - [`plausibility`]: the physical checks every equilibrium passes before it is used (loop
//!   closure, balance, force limits, ψ near γ2, near the rigid model); [`fegm_checked`] is the
//!   guarded solve (warm, else cold, else an error the caller answers with the rigid model);
//! - [`baseline`]: the statistical (5.1) and least-squares (5.2) redundant forward models;
//! - [`fe`]: the finite-element model (5.4: planar beams for rods, platform and carriers,
//!   revolute joints), thermo-mechanical and actuator-displacements methods, and the
//!   comparison of all methods.
//!
//! Conventions: rod force positive in tension; drive force positive when the drive pushes its
//! carrier towards larger q; redundancy current = drive force / 8,600 N · 100 %.

pub mod baseline;
pub mod fe;
mod guarded;
pub mod limits;
pub mod plausibility;
pub mod preload;
pub mod spring;

pub use fe::{fe_solve, FeEquilibrium, FeError, FeMethod, FeModel, FeStiffness};
pub use guarded::{fegm, fegm_checked, fegm_checked_after, fegm_from, Checked};
pub use limits::{wrap_angle, Limits, Reason, RigidPose, Violation};
pub use preload::{compatibility, offset_effect, preload_offsets, Compatibility, PreloadPlan};
pub use spring::{
    fegm_unchecked, platform_balance, sensitivity, ElasticError, ElasticSensitivity, Equilibrium,
    Followers, Stiffness, ALL_ACTIVE, DEFAULT_ROD_STIFFNESS_N_PER_MM, FOLLOWERS_23,
    NOMINAL_DRIVE_FORCE_N,
};
