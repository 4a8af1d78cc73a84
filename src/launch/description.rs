//! What a launch file describes: the processes to run and how, and the environment they get.
//! Parsed by `parse.rs`, run by the supervisor and the managed bring-up.

use std::ffi::OsString;
use std::path::PathBuf;

/// What a launched process runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaunchProgram {
    /// `rpkm-node EXEC --name NAME --params ... ARGS`: a node of [`EXECUTABLES`], in the
    /// node program (`rpkm node EXEC ...` where that is missing).
    Node,
    /// `rpkm EXEC ARGS`: one of [`COMMANDS`] (an `executable` entry).
    Command,
}

/// The rpkm commands an `executable` entry may run.
pub const COMMANDS: [&str; 2] = ["record", "replay"];

/// One process to run.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSpec {
    /// A node or an rpkm command.
    pub program: LaunchProgram,
    /// Node executable (one of [`EXECUTABLES`]) or rpkm command (one of [`COMMANDS`]).
    pub exec: String,
    /// Node name.
    pub name: String,
    /// Parameter files, in order.
    pub param_files: Vec<PathBuf>,
    /// Inline parameters as `key=value`.
    pub params: Vec<String>,
    /// Extra command-line arguments.
    pub args: Vec<String>,
    /// Its namespace (`namespace:`), when not rpkm's default.
    pub namespace: Option<String>,
    /// Topic remapping rules (`remap: [{from, to}]`), in order.
    pub remaps: Vec<(String, String)>,
    /// Its SROS2 enclave (`enclave:`), when not the node's default `/rpkm/<name>`.
    pub enclave: Option<String>,
    /// Started unconfigured and brought up (configure, activate) by the launch, in file
    /// order (`managed: true`).
    pub managed: bool,
    /// Restart when it crashes.
    pub respawn: bool,
    /// First restart delay, s.
    pub respawn_delay: f64,
    /// Line of its entry in the launch file.
    pub line: usize,
}

/// A parsed launch description.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchDescription {
    /// The launch file, as messages name it.
    pub file: String,
    /// The nodes, in file order.
    pub nodes: Vec<NodeSpec>,
    /// Environment set for the nodes (`set_env`).
    pub env: Vec<(String, String)>,
}

impl NodeSpec {
    /// The arguments that start it after its program: `rpkm-node` for a node (after `rpkm
    /// node` the same), `rpkm` for a command.
    pub fn argv(&self) -> Vec<OsString> {
        let mut argv: Vec<OsString> = Vec::new();
        if self.program == LaunchProgram::Node {
            // `--name=`, `--param=`: a value that starts with `-` stays a value
            let name = format!("--name={}", self.name);
            argv.extend([&self.exec, &name].map(OsString::from));
            if self.managed {
                argv.push("--unconfigured".into());
            }
            for f in &self.param_files {
                let mut arg = OsString::from("--params=");
                arg.push(f);
                argv.push(arg);
            }
            for p in &self.params {
                argv.push(OsString::from(format!("--param={p}")));
            }
        } else {
            argv.push(OsString::from(&self.exec));
        }
        argv.extend(self.args.iter().map(OsString::from));
        // last: `--ros-args` takes every word after it
        if self.namespace.is_some() || !self.remaps.is_empty() || self.enclave.is_some() {
            argv.push("--ros-args".into());
            let rules = self.namespace.iter().map(|ns| format!("__ns:={ns}"));
            let rules = rules.chain(self.remaps.iter().map(|(f, t)| format!("{f}:={t}")));
            for rule in rules {
                argv.extend(["-r".into(), OsString::from(rule)]);
            }
            if let Some(e) = &self.enclave {
                argv.extend(["--enclave".into(), OsString::from(e)]);
            }
        }
        argv
    }
}
