//! Which binary starts each process: a node runs in the node program `rpkm-node` found beside
//! the running `rpkm` (the node set alone, no charts, terminal monitor or keystore writer), a
//! command (`rpkm record`) in `rpkm` itself. Without `rpkm-node` there, the nodes run as
//! `rpkm node ...`: the same nodes in the whole command line, as the launch says once.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::description::{LaunchProgram, NodeSpec};
use rpkm_nodes::program::NODE_PROGRAM;

/// The binaries a launch starts its processes with.
#[derive(Debug, Clone)]
pub struct Programs {
    /// The running `rpkm`.
    pub rpkm: PathBuf,
    /// `rpkm-node` beside it, when it is there.
    pub node: Option<PathBuf>,
}

impl Programs {
    /// The programs beside `rpkm`, the running binary.
    pub fn beside(rpkm: &Path) -> Self {
        let node = rpkm.with_file_name(NODE_PROGRAM);
        Self {
            rpkm: rpkm.to_owned(),
            node: node.is_file().then_some(node),
        }
    }

    /// What the launch says when the node program is missing (`None` when it is there).
    pub fn missing_note(&self) -> Option<String> {
        self.node.is_none().then(|| {
            format!(
                "{NODE_PROGRAM} not found beside {}: the nodes run as `rpkm node ...`, each \
                 process the whole command line (build or install both binaries: `cargo \
                 build`, `cargo install --path .`)",
                self.rpkm.display()
            )
        })
    }

    /// The program and its arguments that start `spec`.
    pub fn command(&self, spec: &NodeSpec) -> (&Path, Vec<OsString>) {
        match (spec.program, &self.node) {
            (LaunchProgram::Node, Some(node)) => (node, spec.argv()),
            (LaunchProgram::Node, None) => {
                let mut argv = vec![OsString::from("node")];
                argv.extend(spec.argv());
                (&self.rpkm, argv)
            }
            (LaunchProgram::Command, _) => (&self.rpkm, spec.argv()),
        }
    }
}
