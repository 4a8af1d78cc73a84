//! rpkm-core: the physics of the Scissors-Kinematics (geometry, elastic model, calibration,
//! analysis, diagnosis). Pure: no I/O, no async, no transport. Lengths in mm, angles in rad,
//! forces in N, as in the thesis.
//!
//! # Concepts
//!
//! - **Parameters** ([`params::Params`]): the 29 lengths and angles of the machine's geometry
//!   (rods, joints, guides); model 24 assumes a perfect parallelogram, model 29 does not.
//! - **Pose**: the four drive positions q1..q4, the platform (x, y, ψ) they hold, and what an
//!   instrument read there. Two drives would suffice: the other two are *redundant*, and any
//!   geometric error makes them fight ([`geometry`] for the rigid loop closure, [`elastic`] for
//!   the deformation and drive forces that result).
//! - **Campaign** ([`campaign::Campaign`]): the poses of one measurement session, as the spec's
//!   CSV; its *setups* group poses measured relative to a *reset* pose.
//! - **Noise** ([`noise::NoiseModel`]): how noisy each instrument and encoder is; a value the
//!   user states and the campaign re-estimates ([`variance`]), never a constant.
//! - **Rows** ([`obs::Residual`]): model minus measurement, weighted by its σ, with its
//!   Jacobian: what calibration minimises and diagnosis inspects.
//! - **Calibration** ([`calib`]): the parameters (and effect parameters) that make the rows
//!   smallest, under a manufacturing-tolerance prior, with their uncertainties.
//! - **Online tracking** ([`online`]): the calibration carried on from the drive forces of a
//!   machine at work, steps and drifts named as they come.
//! - **Effect** ([`effects::Effect`]): a physical cause the geometric model lacks (thermal
//!   expansion, a bowed guide...), bound to a campaign, with its own parameters.
//! - **Diagnosis** ([`diagnose`]): which effect the rows ask for, if any: `missing_effect`,
//!   `unexplained_structure` or `nothing_missing`.
//! - **Twin** (the crate `rpkm-twin`, in `twin/`): a simulated machine and measurement cell
//!   with its own conventions, to test the model against a truth it did not write. It
//!   depends on the core; the core cannot name it.

pub mod analysis;
pub mod calib;
pub mod campaign;
pub mod circular;
pub mod convert;
pub mod design;
pub mod diagnose;
pub mod effects;
pub mod elastic;
pub mod geometry;
pub mod history;
pub mod noise;
pub mod obs;
pub mod observability;
pub mod online;
pub mod params;
pub mod plan;
pub mod returns;
pub mod stats;
pub mod units;
pub mod variance;
