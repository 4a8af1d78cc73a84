//! The ROS 2 node set, one subcommand each: `rpkm node ingest|tcp_estimator|calibrator|
//! preload_monitor`. Thin: topics, parameters, validation and bookkeeping here; every model
//! evaluation is a call into `rpkm_core`. Units: SI on topics and in parameter YAML (m, rad,
//! N, s), mm inside the core; the Parameters message converts in [`geometry`], the live
//! messages through the adapters of [`crate::units`] (`drive_positions_mm`,
//! `set_tcp_position_mm`, `set_follower_offsets_mm`, ...), the rest with its named conversions.
//! Each node's parameters are declared once ([`declare`]).
//!
//! Every node reads ROS 2 parameter YAML ([`params`]), publishes on the configured backend
//! (`--backend ipc|dds|both`) and subscribes on one (`--input-backend`), stops cleanly on
//! SIGINT/SIGTERM ([`shutdown`]) and reports on `/diagnostics`.

pub mod calibrate_action;
pub mod calibration_services;
pub mod calibrator;
pub mod context;
pub mod declare;
pub mod effects;
pub mod geometry;
pub mod history;
pub mod ingest;
pub mod inputs;
pub mod joint_input;
pub mod kept;
pub mod lifecycle;
pub mod live;
pub mod online_tracker;
pub mod params;
pub mod preload_monitor;
pub mod realtime;
pub mod shutdown;
pub mod started;
pub mod tcp_estimator;
pub mod views;
pub mod yaml;

pub use context::{
    bad_param, diagnostic_array, log_line, node_name_error, severity, status, BackendArg,
    CommonArgs, Every, Identity, Idle, NodeContext, NodeSetup, RosArgs, COMMON, NODE_NAME_MAX,
};
pub use geometry::{is_geometry_key, parameters_msg, Geometry, ParametersMsgError, GEOMETRY};
pub use params::{NodeParams, ParamError};

/// `rpkm node <kind>` (and `rpkm-node <kind>`, [`crate::program`]): run one node of the set.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Examples (`rpkm-node NAME ...`, the node program `rpkm launch` \
starts, is the same as `rpkm node NAME ...`):\n  \
rpkm node ingest --source campaign.csv --params launch_scripts/params.yaml\n  \
rpkm node ingest --source joint_states --params cell.yaml --backend dds   # a ros2_control cell\n  \
rpkm node tcp_estimator --params launch_scripts/params.yaml --backend both\n  \
rpkm node tcp_estimator --backend dds --param view_every=80   # PoseStamped + /tf at 100 Hz of 8 kHz\n  \
rpkm node preload_monitor --param warn_percent=20 --param error_percent=50"
)]
pub struct NodeArgs {
    #[command(subcommand)]
    pub kind: NodeKind,
}

/// The four nodes.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum NodeKind {
    /// Validates and republishes ActuatorState/TcpMeasurement from DDS, a ros2_control cell's
    /// JointState, a CSV stream on stdin or a campaign CSV file; rejects are counted on
    /// /diagnostics.
    #[command(name = "ingest")]
    Ingest(ingest::IngestNodeArgs),
    /// Elasto-geometric TCP estimate for every ActuatorState.
    #[command(name = "tcp_estimator")]
    TcpEstimator(CommonArgs),
    /// Calibrates when a campaign ends; publishes Parameters (transient-local).
    #[command(name = "calibrator")]
    Calibrator(CommonArgs),
    /// Predicted vs measured drive forces: OK/WARN/ERROR on /diagnostics and PreloadStatus.
    #[command(name = "preload_monitor")]
    PreloadMonitor(CommonArgs),
}

impl NodeKind {
    /// The executable name as launch files spell it.
    pub fn exec_name(&self) -> &'static str {
        match self {
            Self::Ingest(_) => "ingest",
            Self::TcpEstimator(_) => "tcp_estimator",
            Self::Calibrator(_) => "calibrator",
            Self::PreloadMonitor(_) => "preload_monitor",
        }
    }
}

/// The node executables `rpkm launch` accepts.
pub const EXECUTABLES: [&str; 4] = ["ingest", "tcp_estimator", "calibrator", "preload_monitor"];

/// The parameters node `exec` declares besides [`COMMON`]; `None` for an unknown executable.
pub fn declarations(exec: &str) -> Option<Vec<declare::ParamSpec>> {
    match exec {
        "ingest" => Some(ingest::declarations()),
        "tcp_estimator" => Some(tcp_estimator::declarations()),
        "calibrator" => Some(calibrator::declarations()),
        "preload_monitor" => Some(preload_monitor::declarations()),
        _ => None,
    }
}

/// The parameter keys node `exec` declares besides [`COMMON`]'s; `None` for an unknown
/// executable.
pub fn declared_keys(exec: &str) -> Option<Vec<&'static str>> {
    declarations(exec).map(|d| declare::keys(&[&d]))
}

/// Runs the node `args` names until SIGINT/SIGTERM (or, for ingest, its end of input).
pub fn run(args: &NodeArgs) -> anyhow::Result<()> {
    shutdown::install();
    match &args.kind {
        NodeKind::Ingest(a) => ingest::run(a),
        NodeKind::TcpEstimator(a) => tcp_estimator::run(a),
        NodeKind::Calibrator(a) => calibrator::run(a),
        NodeKind::PreloadMonitor(a) => preload_monitor::run(a),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn words(s: &str) -> Vec<String> {
        s.split_whitespace().map(str::to_owned).collect()
    }

    #[test]
    fn ros_args_give_namespace_name_rules_and_parameters() -> Result<(), String> {
        let r = RosArgs::parse(&words(
            "-r __ns:=/machine_a -r __node:=est_a -r tcp_estimate:=/cell/e -p model:=24 \
             --params-file p.yaml --ros-args -r a:=b -- -r ignored:=x",
        ))?;
        assert_eq!(r.namespace.as_deref(), Some("/machine_a"));
        assert_eq!(r.node.as_deref(), Some("est_a"));
        assert_eq!(
            r.remaps,
            [
                ("tcp_estimate".to_owned(), "/cell/e".to_owned()),
                ("a".to_owned(), "b".to_owned())
            ]
        );
        assert_eq!(r.params, ["model=24"]);
        assert_eq!(r.param_files, [PathBuf::from("p.yaml")]);
        for (bad, says) in [
            ("-r", "expected a value"),
            ("-r nope", "expected FROM:=TO"),
            ("-p model=24", "expected KEY:=VALUE"),
            ("--enclave", "expected a value"),
            ("--log-level debug", "unknown argument \"--log-level\""),
        ] {
            let e = RosArgs::parse(&words(bad)).expect_err(bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
        // rcl's enclave flag, long and short; the last one wins
        let r = RosArgs::parse(&words("--enclave /cell/a -e /cell/b"))?;
        assert_eq!(r.enclave.as_deref(), Some("/cell/b"));
        Ok(())
    }

    /// The node's name, namespace and parameter sections follow `--ros-args`: a section of
    /// the namespace applies, the default namespace's does not.
    #[test]
    fn a_namespaced_node_reads_its_namespace_s_section() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        let file = dir.path().join("p.yaml");
        std::fs::write(
            &file,
            "/rpkm/est_a:\n  ros__parameters:\n    model: 24\n\
             /machine_a/est_a:\n  ros__parameters:\n    stiffness_factor: 2.0\n",
        )?;
        let args = CommonArgs {
            params: vec![file],
            ros_args: words("-r __ns:=/machine_a -r __node:=est_a"),
            ..CommonArgs::default()
        };
        let id = args.identity("tcp_estimator")?;
        assert_eq!(id.name, "est_a");
        assert_eq!(id.names.namespace(), "/machine_a");
        let p = id.params()?;
        assert!((p.f64("stiffness_factor", 1.0)? - 2.0).abs() < 1e-12);
        assert_eq!(
            p.u64("model", 29)?,
            29,
            "the /rpkm section is another node's"
        );
        let bad = CommonArgs {
            ros_args: words("-r __ns:=machine_a"),
            ..CommonArgs::default()
        };
        let e = bad.identity("ingest").expect_err("relative namespace");
        assert!(e.to_string().contains("namespace \"machine_a\""), "{e}");
        Ok(())
    }
}
