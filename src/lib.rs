//! rpkm: the command line of the node set (`rpkm calibrate`, `diagnose`, `node`, `launch`,
//! `monitor`, ...), a thin crate on `rpkm_nodes`. What only the command line links lives here:
//! the subcommands ([`cli`]), the launcher ([`launch`], which may open the [`monitor`]), the
//! terminal monitor (ratatui), the HTML reports ([`report`]) and their charts ([`plot`],
//! plotters), and the SROS2 keystore writer ([`security`], OpenSSL's X.509 and S/MIME).
//!
//! The node set's modules are named where they live (`rpkm_nodes::node`,
//! `rpkm_nodes::topics`, ...): this crate re-exports none of them, so a path says which crate
//! holds the code.

pub mod cli;
pub mod launch;
pub mod monitor;
pub mod plot;
pub mod report;
pub mod security;
