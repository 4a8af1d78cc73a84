//! The core's integration tests, one module per file, linked into one test binary (issue 30:
//! one link instead of one per file). A new test file goes here as `core/tests/it/NAME.rs`
//! with a `mod NAME;` line below; `cargo test -p rpkm-core --test it NAME` runs it alone.
//! Shared helpers are in `support` (`use crate::support;`).

mod support;

mod analysis_table_4_7;
mod calibration_coverage;
mod calibration_currents;
mod calibration_currents_observability;
mod calibration_currents_online;
mod calibration_currents_online_events;
mod calibration_instruments;
mod calibration_leverages;
mod calibration_pieces;
mod calibration_preload_among;
mod calibration_progress;
mod calibration_shared_rows;
mod campaign_proptest;
mod campaign_reader;
mod circular_test;
mod diagnose_periodic;
mod diagnose_prediction;
mod diagnose_twin;
mod diagnose_twin_found;
mod effects_jacobian;
mod elastic_fe;
mod elastic_plausibility;
mod elastic_spring;
mod geometry_round_trip;
mod history_change;
mod history_trend;
mod plan_accuracy;
mod plan_separate;
mod plan_thesis;
mod returns_drift;
mod twin_campaigns;
mod written_effects;
