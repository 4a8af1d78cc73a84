//! Finite-element elasto-geometric model of the Scissors-Kinematics (thesis 5.4 and its
//! adaptations to redundancy): a linear planar frame of 2-node Euler-Bernoulli beams for the
//! rods, the platform and the carriers, revolute joints at the rod ends (ideal pins or
//! rotational springs), carriers held across their guides, drives that hold their position
//! (rigidly or through a translational spring) or follow freely.
//!
//! The mesh is laid on the rigid configuration of a non-redundant pair of active drives
//! (nodes at the joint positions of that assembled pose); the redundant drives' parameter
//! incompatibility is then imposed in one of the thesis's two ways ([`FeMethod`]):
//! - thermo-mechanical: the carriers sit at their commanded positions and each rod whose length
//!   does not fit the gap gets the misfit as an initial ("thermal") elongation;
//! - actuator-displacements: the carriers sit where the rods fit (rgm), and each redundant
//!   drive is displaced by the difference to its command.
//!
//! The outputs are the platform TCP displacement from the rigid pose, rod axial forces, drive
//! forces and redundancy currents, with the conventions of [`crate::elastic`].
//!
//! - [`beam`]: the element; [`assembly`]: structure and solver; [`machine`]: the mesh of the
//!   Scissors-Kinematics and its default sections; [`methods`]: the two methods and the
//!   reusable [`FeModel`]; [`compare`]: all redundant forward models on the same cases.

pub mod assembly;
pub mod beam;
pub mod compare;
mod error;
pub mod machine;
pub mod methods;

pub use beam::Section;
pub use compare::{compare_methods, Comparison, ComparisonError, MethodResult, RedundantModel};
pub use error::FeError;
pub use error::{DofLabel, Label};
pub use machine::{FeStiffness, RodEndJoint};
pub use methods::{fe_solve, FeEquilibrium, FeMethod, FeModel};
