//! Units between the core and the topics: the core works in mm, rad, N, s (the thesis's),
//! the ROS topics in SI (REP 103), a person reads µm, mrad and ms. The factors and their
//! named conversions are the core's ([`rpkm_core::units`], one definition for the whole
//! workspace), re-exported here for the message adapters (`campaign_bag`, the Parameters
//! message of `node::geometry`) and the nodes, which convert with
//! these named functions, never with a bare factor (tests/layers.rs holds it).

pub use rpkm_core::units::*;
