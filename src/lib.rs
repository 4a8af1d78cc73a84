//! rpkm: the command line of the node set (`rpkm calibrate`, `diagnose`, `node`, `launch`,
//! `monitor`, ...), a thin crate on `rpkm_nodes`. What only the command line links lives here:
//! the subcommands ([`cli`]), the launcher ([`launch`], which may open the [`monitor`]), the
//! terminal monitor (ratatui), the HTML reports ([`report`]) and their charts ([`plot`],
//! plotters), and the SROS2 keystore writer ([`security`], OpenSSL's X.509 and S/MIME).
//!
//! The node set's modules are re-exported under their old paths (`rpkm::node`,
//! `rpkm::topics`, ...), so that the command line and the tests name one module one way.

pub mod cli;
pub mod launch;
pub mod monitor;
pub mod plot;
pub mod report;
pub mod security;

pub use rpkm_nodes::{
    campaign_bag, effects_file, error, history, input, logging, node, program, stream, topics,
    units, words,
};
