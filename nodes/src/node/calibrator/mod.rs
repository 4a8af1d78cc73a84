//! `calibrator`: accumulates TcpMeasurements with the ActuatorState of the same stamp, per
//! setup, into a campaign (`crate::campaign_bag::CampaignAssembler`, the same mapping as the
//! bag tools) and runs the calibration every command shares
//! (`rpkm_core::calib::calibrate_command`) when the campaign ends:
//! - an end-of-campaign marker (a TcpMeasurement with setup
//!   [`crate::node::ingest::END_OF_CAMPAIGN`]: ingest sends it at the end of a file; any publisher
//!   may send it to request a calibration),
//! - `calibrate_every` measurements (0: off),
//! - `idle_end_s` seconds without a measurement (0: off).
//!
//! Setups whose name starts with `validation_prefix` are held out: they give `val_rms`. The
//! result goes out as Parameters (reliable, transient-local: late joiners get it) and, once
//! Diagnosis (`rpkm_core::diagnose`, [`diagnose`]).
//!
//! With `online: true` it also tracks the geometry live from the drive forces (issue 15,
//! [`crate::node::online_tracker`]):
//! every `online_decimation`-th ActuatorState with all four drives position-controlled goes
//! to `rpkm_core::online` on a worker thread (the loop hands it over without waiting;
//! a full hand-over queue is counted, never waited on), which publishes Parameters with their
//! σ when a parameter moved by `online_publish_sigma` σ since the last, and a WARN on
//! /diagnostics naming a step change, or a drift: a rod's creep explaining the change since
//! the drift test's reference beyond what noise alone would have (`DriftMonitor`, at a false
//! alarm of 1e-6 a check) and its change beyond `online_drift_warn_um` ("l3 +48 µm in 6 min
//! (+12.0 ± 0.3 µm/K)", or "l1..l5 alike in 2 min, the path cannot tell which: ..." where the
//! path does not name one rod).
//!
//! Files, one job each:
//! - `params.rs`: The node's parameters: keys, ROS descriptors and the typed settings, the
//!   online tracker's among them.
//! - `job.rs`: A calibration job: the campaign split into fit and validation, the options,
//!   the calibration run.
//! - `diagnosis.rs`: The diagnosis of the calibrated model and its Diagnosis message.
//! - `parameters.rs`: The calibration as a Parameters message, its effects' values included.
//! - `goal.rs`: A Calibrate goal's options and its result.
//! - `accumulator.rs`: Measurements and actuator states of the same stamp accumulated into a
//!   campaign, per setup.
//! - `start_covariance.rs`: The start covariance of the online tracker, read from a geometry
//!   file's JSON.
//! - `node.rs`: The node: its inputs, when a campaign ends, the calibration published, its
//!   history, the loop.
//! - `tests.rs`: the module's unit tests.

mod accumulator;
mod diagnosis;
mod goal;
mod job;
mod node;
mod parameters;
mod params;
mod start_covariance;
#[cfg(test)]
mod tests;

pub use accumulator::Accumulator;
pub use job::{
    calibrate_campaign, calibrate_job, CalibratorOptions, Job, JobOutcome, SelectionRule,
};
pub use node::run;
pub use params::{declarations, declared, PARAMS};
pub use start_covariance::start_covariance;
