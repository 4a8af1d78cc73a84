//! The launcher's command line and its errors.

use rpkm_nodes::node::params::YamlSyntax;
use std::path::PathBuf;

/// `rpkm launch`.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Examples:\n  rpkm launch launch_scripts/rpkm.launch.yaml backend:=both\n  \
rpkm launch launch_scripts/rpkm.launch.yaml source:=campaign.csv record:=true bag_dir:=runs\n  \
rpkm launch launch_scripts/rpkm.launch.yaml source:=joint_states params_file:=cell.yaml\n\n\
The shipped launch file: params_file:=FILE is a parameter file of the cell's own, read by \
every node after params.yaml (a later file's value replaces an earlier one's, as in ROS 2); \
backend:=ipc|dds|both, by default both with source:=joint_states (a ros2_control cell is on \
DDS), else ipc.\n\n\
Entries: arg, let (a variable set, with if:/unless:), node (rpkm nodes, started as the \
rpkm-node program beside rpkm, else as `rpkm node`), executable (`cmd: rpkm record ...` or \
`rpkm replay ...`), set_env; `if:`/`unless:` switch a node or executable; substitutions \
$(var NAME), $(env NAME [DEFAULT]), $(dirname), $(equals A B). Ctrl-C (or SIGTERM) stops \
every process (a recorder closes its bag); a node that crashes is restarted with backoff."
)]
pub struct LaunchArgs {
    /// Launch description (ROS 2 launch YAML).
    pub file: PathBuf,
    /// Launch arguments as NAME:=VALUE (the shipped file's: source, backend, params_file,
    /// record, bag_dir, namespace, geometry_file, effects_file).
    pub args: Vec<String>,
    /// Check the launch file and every node's command line and parameters (files, declared
    /// keys, backends, geometry), start nothing: exit 0, or 2 naming the file and line.
    #[arg(long)]
    pub check: bool,
}

/// A launch description that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    #[error("{file}: cannot read: {source}")]
    Read {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}:{line}: invalid UTF-8 at byte {offset}, expected UTF-8 text")]
    Utf8 {
        file: String,
        line: usize,
        offset: usize,
    },
    #[error(transparent)]
    Yaml(#[from] YamlSyntax),
    /// An entry that cannot be used, at `line` (its key's, else the entry's first).
    #[error("{file}:{line}: {what}")]
    Invalid {
        file: String,
        line: usize,
        what: String,
    },
    /// A `NAME:=VALUE` of the command line.
    #[error("{file}: {what}")]
    Argument { file: String, what: String },
}
