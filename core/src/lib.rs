//! rpkm-core: the physics of the Scissors-Kinematics (geometry, elastic model, calibration,
//! analysis, diagnosis). Pure: no I/O, no async, no transport. Lengths in mm, angles in rad,
//! forces in N, as in the thesis.

pub mod analysis;
pub mod calib;
pub mod campaign;
pub mod circular;
pub mod design;
pub mod diagnose;
pub mod effects;
pub mod elastic;
pub mod geometry;
pub mod noise;
pub mod obs;
pub mod observability;
pub mod params;
pub mod twin;
pub mod variance;
