//! `rpkm launch FILE [name:=value ...]`: launch descriptions in the ROS 2 launch YAML dialect,
//! started and supervised by [`supervisor`].
//!
//! ```yaml
//! launch:
//!   - arg: {name: backend, default: ipc}
//!   - node:
//!       pkg: rpkm
//!       exec: tcp_estimator          # ingest | tcp_estimator | calibrator | preload_monitor
//!       name: tcp_estimator          # parameter section, iceoryx2/DDS node name
//!       param:
//!         - from: params.yaml        # relative to this file's folder
//!         - {name: model, value: 29}
//!         - {name: geometry_file, value: $(var geometry_file)}   # not passed when empty
//!       args: --backend $(var backend)
//!       respawn: true                # default true: restarted with backoff when it crashes
//!       respawn_delay: 0.2           # s, doubled per quick crash, at most 5 s
//!       namespace: /machine_a        # its topics, services, parameters (default /rpkm)
//!       managed: true                # started unconfigured, configured and activated by
//!                                    # the launch in file order (default false: active)
//!       remap: [{from: tcp_estimate, to: /cell/estimate_a}]   # topic remapping
//!       enclave: /rpkm/tcp_estimator # SROS2 enclave (default /rpkm/<name>), used with
//!                                    # ROS_SECURITY_ENABLE=true
//!   - let: {name: backend, value: both, if: "$(equals $(var source) joint_states)"}
//!   - set_env: {name: ROS_DOMAIN_ID, value: "7"}
//!   - executable:                    # another rpkm command, e.g. the recorder
//!       cmd: rpkm record --out $(var bag) --topics /rpkm/tcp_estimate,/diagnostics
//!       name: recorder               # default: the subcommand
//!       respawn: false               # default false for executables
//!       if: $(var record)            # node and executable: started only if true (`unless`)
//! ```
//!
//! A node restarted by the launch comes back with the parameter values set at run time through
//! its parameter services (kept in a folder of the launch's, `RPKM_STATE_DIR`, made fresh at
//! every launch and removed at its end) and says which at its start.
//!
//! The recorder stops with the launch: SIGTERM makes `rpkm record` write what is queued and
//! close its bag (metadata.yaml and summary).
//!
//! A `{name, value}` parameter whose value is empty after substitution is not passed: a launch
//! argument left at an empty default (`geometry_file:=`) leaves the parameter files' value.
//!
//! Keys other than these are errors naming the key and its line (a typo such as `If:` would
//! otherwise switch a recorder on). `respawn_delay` is bounded to 0..=3600 s. Every error
//! names the file and a line: the key's, else its entry's.
//!
//! `rpkm launch FILE --check` starts nothing: it reads the file and, for every node, parses its
//! command line and loads and checks its parameters as the node does before it opens its
//! transport ([`NodeSetup`] and the geometry); exit 0, or 2 naming the node's line.
//!
//! Substitutions in every string: `$(var NAME)` (an `arg`, overridden by `NAME:=VALUE` on the
//! command line, or a `let`: ROS 2's SetLaunchConfiguration, from its entry on, when its
//! `if:`/`unless:` say so), `$(env NAME)` / `$(env NAME DEFAULT)`, `$(dirname)` (this file's
//! folder), `$(equals A B)` (`true`/`false`, as ROS 2's: booleans and numbers compare as
//! such); a substitution's arguments may be substitutions.
//!
//! A `{from: FILE}` parameter file written in the launch file is relative to its folder; one
//! a substitution gave (`$(var params_file)`) is used as given, relative to the working
//! directory; empty after substitution, no file.
//!
//! Files, one job each:
//! - `args.rs`: The launcher's command line and its errors.
//! - `place.rs`: Where an error is: the entry being read, a key's line, a line serde_yaml did
//!   not give.
//! - `fields.rs`: What entries share: the keys each may have, a key's value, flags,
//!   `if`/`unless` and respawn.
//! - `parse.rs`: A launch file read into its description: arguments, `arg`, `set_env` and
//!   `executable` entries.
//! - `node_entry.rs`: A `node` entry: lifecycle management, SROS2 enclave, name, namespace
//!   and remappings.
//! - `check.rs`: `rpkm launch --check`: every node's command line and configuration as it
//!   would start.
//! - `description.rs`: What a launch file describes: the processes, how they run, their
//!   environment.
//! - `programs.rs`: Which binary starts each process: `rpkm-node` beside `rpkm` for a node
//!   (`rpkm node` without it), `rpkm` for a command.
//! - `supervisor.rs`: The nodes started as processes and supervised: restarts with backoff,
//!   shutdown on a signal.
//! - `ready.rs`: The nodes started one at a time: the pipe on which a node says it has
//!   started, and the bounded wait for it.
//! - `managed.rs`: The managed nodes brought up in file order through their lifecycle.
//! - `state_dir.rs`: The folder where the nodes keep the parameter values set at run time
//!   across their restarts, fresh at every launch.
//! - `tests.rs`: the module's unit tests.

mod args;
mod check;
mod description;
mod fields;
mod managed;
mod node_entry;
mod parse;
mod place;
mod programs;
mod ready;
mod state_dir;
pub mod supervisor;
#[cfg(test)]
mod tests;

pub use args::{LaunchArgs, LaunchError};
pub use description::{LaunchDescription, LaunchProgram, NodeSpec, COMMANDS};

use check::check;

/// Runs `rpkm launch`.
pub fn run(args: &LaunchArgs) -> anyhow::Result<()> {
    let desc = LaunchDescription::load(&args.file, &args.args)
        .map_err(|e| rpkm_nodes::error::bad_input(e.to_string()))?;
    if args.check {
        return check(&desc);
    }
    // A node restarted by the launch comes back with the values set at run time; a new
    // launch starts from the files.
    let state = state_dir::StateDir::create();
    let desc = LaunchDescription {
        env: state.env(&desc.env),
        ..desc
    };
    supervisor::run(&desc)
}
