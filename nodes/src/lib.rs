//! The rpkm node set: command line, nodes, reports. Physics lives in `rpkm_core`.

pub mod cli;
pub mod plot;
