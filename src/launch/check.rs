//! `rpkm launch --check`: every node's command line and configuration as it would start.

use super::description::{LaunchDescription, LaunchProgram, NodeSpec};
use super::programs::Programs;
use rpkm_nodes::node::{declared_keys, Geometry, NodeArgs, NodeKind, NodeSetup};
use rpkm_nodes::program::NODE_PROGRAM;

/// `rpkm launch --check`: every node's command line and configuration as it would start,
/// nothing started. An `executable` entry's command line is checked when it starts.
pub(super) fn check(desc: &LaunchDescription) -> anyhow::Result<()> {
    let exe = std::env::current_exe()?;
    let programs = Programs::beside(&exe);
    if let Some(note) = programs.missing_note() {
        println!("{note}");
    }
    for spec in &desc.nodes {
        let (program, argv) = programs.command(spec);
        let program = program.file_name().unwrap_or_default().to_string_lossy();
        let argv: Vec<String> = argv
            .iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        if spec.program == LaunchProgram::Node {
            check_node(spec).map_err(|e| {
                rpkm_nodes::error::bad_input(format!(
                    "{}:{}: node {}: {}",
                    desc.file,
                    spec.line,
                    spec.name,
                    rpkm_nodes::error::error_chain(&e)
                ))
            })?;
        }
        println!(
            "{}:{}: {}: {program} {}",
            desc.file,
            spec.line,
            spec.name,
            argv.join(" ")
        );
    }
    Ok(())
}

/// Parses a node's command line as `rpkm-node` would and loads and checks its parameters:
/// files, declared keys, backends, diagnostics period, geometry.
fn check_node(spec: &NodeSpec) -> anyhow::Result<()> {
    use clap::{Args, FromArgMatches};
    let argv = std::iter::once(NODE_PROGRAM.into()).chain(spec.argv());
    let args = NodeArgs::augment_args(clap::Command::new(NODE_PROGRAM))
        .try_get_matches_from(argv)
        .and_then(|m| NodeArgs::from_arg_matches(&m))
        .map_err(|e| {
            let text = e.render().to_string();
            let first = text.lines().next().unwrap_or_default();
            anyhow::anyhow!("args: {}", first.trim_start_matches("error: "))
        })?;
    let kind = args.kind.exec_name();
    let declared = declared_keys(kind).unwrap_or_default();
    let (common, geometry) = match &args.kind {
        NodeKind::Ingest(a) => (&a.common, false),
        NodeKind::TcpEstimator(c) | NodeKind::Calibrator(c) | NodeKind::PreloadMonitor(c) => {
            (c, true)
        }
    };
    let setup = NodeSetup::load(kind, common, &declared, None)?;
    if geometry {
        Geometry::from_params(&setup.params)?;
    }
    // the JointState input's settings: read by the three nodes that take drive states
    if !matches!(args.kind, NodeKind::Calibrator(_)) {
        rpkm_nodes::node::joint_input::JointConfig::from_params(&setup.params)
            .map_err(rpkm_nodes::node::bad_param)?;
    }
    Ok(())
}
