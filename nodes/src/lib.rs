//! The rpkm node set: command line, nodes, reports. Physics lives in `rpkm_core`.

pub mod campaign_bag;
pub mod cli;
pub mod effects_file;
pub mod error;
pub mod history;
pub mod input;
pub mod launch;
pub mod logging;
pub mod monitor;
pub mod node;
pub mod plot;
pub mod report;
pub mod security;
pub mod stream;
pub mod topics;
pub mod units;
pub mod words;
