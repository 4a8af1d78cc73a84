//! rpkm-nodes: the ROS 2 node set of rpkm and what its nodes are made of. Physics lives in
//! `rpkm_core`, the wire and the bags in `rpkm_transport`; the command line (`rpkm`, src/)
//! sits on top and adds the launcher, the terminal monitor, the reports and their charts, and
//! the SROS2 keystore writer, none of which a node links (the nodes read a keystore through
//! `rpkm_transport::security`).
//!
//! - [`node`]: the four nodes (`ingest`, `tcp_estimator`, `preload_monitor`, `calibrator`),
//!   their parameters, real-time set-up, lifecycle and shutdown; `rpkm node` runs one.
//! - [`program`]: `rpkm-node`, the nodes as a program of their own (what `rpkm launch`
//!   starts): this crate alone, none of the command line's crates.
//! - [`topics`]: the topic names; [`units`]: SI on the topics, mm in the core, converted here.
//! - [`campaign_bag`]: a campaign as a bag of messages and back; [`stream`]: the actuator
//!   stream of a campaign.
//! - [`input`]: the file readers the nodes and the commands share; [`effects_file`]: written
//!   effects from YAML, each error at its line and column.
//! - [`history`]: a calibration made into the machine's history record, the records analysed
//!   and in words.
//! - [`words`]: figures of the diagnosis and the online tracker in sentences.
//! - [`error`]: typed errors and exit codes; [`logging`]: warnings to stderr.

pub mod calibration_file;
pub mod campaign_bag;
pub mod effects_file;
pub mod error;
pub mod history;
pub mod input;
pub mod logging;
pub mod node;
pub mod program;
pub mod stream;
pub mod topics;
pub mod units;
pub mod words;
