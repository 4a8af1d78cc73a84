//! The command line's and the nodes' integration tests, one module per file, linked into one
//! test binary: each `tests/*.rs` file used to be its own binary linking the whole command
//! line, which made the test build most of CI's time (issue 30). A new test file goes here as
//! `tests/it/NAME.rs` with a `mod NAME;` line below; `cargo test --test it NAME` runs it
//! alone. Shared helpers are the `*_support` modules (`use crate::node_support;`).
//! `tests/bag_cli.rs` stays a binary of its own (why: at its `mod bag_support`).

use std::sync::Mutex;

/// Held by every test that SIGKILLs a node (tcp_estimator): iceoryx2's dead-node
/// clean-up is machine-wide, so another test's process may remove a killed node's resources
/// before the test that killed it has seen what it checks. The files were separate binaries,
/// run one after the other; as modules of one they run side by side.
pub static KILLS_A_NODE: Mutex<()> = Mutex::new(());

mod bag_support;
mod diagnosis_support;
mod fastdds_support;
mod foreign_support;
mod fuzz_support;
mod history_support;
mod joint_states_support;
mod node_support;
mod security_support;
mod shared_support;

mod bag_nodes;
mod bag_reference;
mod bag_rosbag2_metadata;
mod calibration_one_owner;
mod cli_bad_config;
mod cli_bad_input;
mod cli_calibrate;
mod cli_diagnose;
mod cli_effects_file;
mod cli_foreign;
mod cli_lag;
mod cli_plan;
mod cli_scipy_baseline;
mod cli_words;
mod dds_large_samples;
mod docs_in_repo;
mod first_campaign_doc;
mod first_use_nodes;
mod first_use_period;
mod first_use_words;
mod fuzz_inputs;
mod history_credentials;
mod history_kill;
mod history_outage;
mod history_postgres;
mod history_twin;
mod ingest_grammar;
mod launch_cell;
mod launch_params_file;
mod library_described;
mod monitor_foxglove_layout;
mod monitor_tmux;
mod node_calibrate_action;
mod node_calibration_services;
mod node_calibrator_history;
mod node_diagnosis_effects;
mod node_estimator_effects;
mod node_estimator_foreign;
mod node_estimator_jumps;
mod node_ingest_cyclone;
mod node_joint_states;
mod node_joint_states_fastdds;
mod node_joint_states_positions;
mod node_joint_states_qos;
mod node_kept_params;
mod node_launch_restart;
mod node_lifecycle;
mod node_netns_dds;
mod node_online_follow;
mod node_params_declared;
mod node_preload_monitor;
mod node_ros2_params;
mod node_ros2_views;
mod node_services_fastdds;
mod node_soak;
mod plan_foreign;
mod report_alignment;
mod report_chromium;
mod ros_interface_package;
mod security_cell;
mod security_keystore;
mod security_nodes;
