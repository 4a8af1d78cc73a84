//! Starts the nodes of a launch description as processes of this very binary
//! (`rpkm node <exec> --name <name> --params ...`) and supervises them:
//! - a node that dies (non-zero exit or a signal) is restarted when `respawn` is on, after
//!   `respawn_delay` doubled for every crash within 10 s of its start (at most 5 s); exit
//!   code 0 (input done) and 2 (bad configuration: restarting cannot help) are final, and
//!   a node that exited 2 makes the launch exit 2 too, naming it;
//! - before the first start and after every death, the iceoryx2 resources of dead processes
//!   are removed (a SIGKILLed node leaves its shared memory behind);
//! - SIGINT/SIGTERM: SIGTERM to every node, SIGKILL after 5 s for those still running.
//!
//! Events go to stderr as `[launch] ...` lines: `started NAME pid PID`, `NAME pid PID
//! exited ...`, `restarting NAME in S s`.

use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

use anyhow::Context;

use super::{LaunchDescription, NodeSpec};
use crate::node::shutdown;

/// A node's crash within this time of its start doubles the next restart delay.
const QUICK_CRASH: Duration = Duration::from_secs(10);
/// Largest restart delay.
const MAX_DELAY: Duration = Duration::from_secs(5);
/// Time the nodes get to stop after SIGTERM.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);
/// Supervision period.
const TICK: Duration = Duration::from_millis(10);

enum State {
    Running { child: Child, since: Instant },
    Waiting { until: Instant },
    Done,
}

struct Supervised<'a> {
    spec: &'a NodeSpec,
    state: State,
    quick_crashes: u32,
}

/// One `[launch]` line in one write: the nodes share this stderr, and a line written in
/// pieces would interleave with theirs.
fn log(msg: impl std::fmt::Display) {
    crate::node::log_line("launch", msg);
}

fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exited with code {c}"),
        (None, Some(s)) => format!("killed by signal {s}"),
        _ => "ended".into(),
    }
}

fn spawn(exe: &Path, spec: &NodeSpec, env: &[(String, String)]) -> anyhow::Result<Child> {
    let mut cmd = Command::new(exe);
    cmd.args(spec.argv());
    cmd.envs(env.iter().map(|(k, v)| (k, v)));
    let child = cmd
        .spawn()
        .with_context(|| format!("starting node {} ({})", spec.name, exe.display()))?;
    log(format!("started {} pid {}", spec.name, child.id()));
    Ok(child)
}

/// Removes the iceoryx2 resources of dead processes (a node creation does the same; this
/// one also covers nodes that are not restarted).
fn cleanup_dead() {
    match rpkm_transport::ipc::IpcNode::new(&format!("rpkm_launch_{}", std::process::id()), "") {
        Ok(node) => {
            let (cleaned, failed) = node.cleanup_dead_nodes();
            if cleaned > 0 || failed > 0 {
                log(format!(
                    "removed the iceoryx2 resources of {cleaned} dead nodes ({failed} failed)"
                ));
            }
        }
        Err(e) => log(format!("iceoryx2 cleanup skipped: {e}")),
    }
}

fn signal(child: &Child, sig: libc::c_int) {
    if let Ok(pid) = libc::pid_t::try_from(child.id()) {
        // SAFETY: kill(2) on the pid of our own child, which has not been reaped yet (we hold
        // its `Child` and only reap through it), so the pid cannot have been reused.
        unsafe {
            libc::kill(pid, sig);
        }
    }
}

/// What became of a node whose process ended.
fn reaped(n: &mut Supervised<'_>, status: ExitStatus, lived: Duration, failed: &mut Vec<String>) {
    // Exit 2 is a configuration error: restarting cannot help, and the launch must say so
    // in its own exit code.
    if status.code() == Some(2) {
        failed.push(n.spec.name.clone());
    }
    let final_exit = matches!(status.code(), Some(0 | 2));
    if final_exit || !n.spec.respawn {
        n.state = State::Done;
        return;
    }
    n.quick_crashes = if lived < QUICK_CRASH {
        n.quick_crashes.saturating_add(1)
    } else {
        0
    };
    let factor = 2f64.powi(i32::try_from(n.quick_crashes.saturating_sub(1).min(16)).unwrap_or(16));
    // Capped in seconds before the `Duration` exists: from_secs_f64 panics on values
    // beyond its range.
    let delay = Duration::from_secs_f64(
        (n.spec.respawn_delay * factor).clamp(0.0, MAX_DELAY.as_secs_f64()),
    );
    log(format!(
        "restarting {} in {:.2} s",
        n.spec.name,
        delay.as_secs_f64()
    ));
    n.state = State::Waiting {
        until: Instant::now() + delay,
    };
}

/// SIGTERM to every running node, SIGKILL to those still running after [`STOP_TIMEOUT`].
fn stop_all(nodes: &mut [Supervised<'_>]) {
    log("stopping every node");
    for n in nodes.iter() {
        if let State::Running { child, .. } = &n.state {
            signal(child, libc::SIGTERM);
        }
    }
    let deadline = Instant::now() + STOP_TIMEOUT;
    for n in nodes.iter_mut() {
        if let State::Running { child, .. } = &mut n.state {
            loop {
                match child.try_wait() {
                    Ok(Some(status)) => {
                        log(format!("{} {}", n.spec.name, describe(status)));
                        break;
                    }
                    Ok(None) if Instant::now() < deadline => std::thread::sleep(TICK),
                    _ => {
                        log(format!("{} did not stop: SIGKILL", n.spec.name));
                        let _ = child.kill();
                        let _ = child.wait();
                        break;
                    }
                }
            }
        }
    }
    cleanup_dead();
}

/// The launch's outcome: bad input (exit 2) when nodes rejected their configuration.
fn outcome(failed: &[String]) -> anyhow::Result<()> {
    if failed.is_empty() {
        return Ok(());
    }
    Err(crate::error::bad_input(format!(
        "{} node(s) failed their configuration (exit 2, not restarted): {}",
        failed.len(),
        failed.join(", ")
    )))
}

/// Runs the description until SIGINT/SIGTERM or until every node is done; an error when a
/// node rejected its configuration.
pub fn run(desc: &LaunchDescription) -> anyhow::Result<()> {
    shutdown::install();
    let exe = std::env::current_exe().context("locating the rpkm binary")?;
    cleanup_dead();
    let mut nodes: Vec<Supervised<'_>> = Vec::new();
    for spec in &desc.nodes {
        let child = spawn(&exe, spec, &desc.env)?;
        nodes.push(Supervised {
            spec,
            state: State::Running {
                child,
                since: Instant::now(),
            },
            quick_crashes: 0,
        });
    }
    let mut failed = Vec::new();
    while !shutdown::requested() {
        let mut any_alive = false;
        for n in &mut nodes {
            match &mut n.state {
                State::Running { child, since } => {
                    any_alive = true;
                    let Some(status) = child.try_wait().context("waiting for a node")? else {
                        continue;
                    };
                    let lived = since.elapsed();
                    log(format!(
                        "{} pid {} {}",
                        n.spec.name,
                        child.id(),
                        describe(status)
                    ));
                    cleanup_dead();
                    reaped(n, status, lived, &mut failed);
                }
                State::Waiting { until } => {
                    any_alive = true;
                    if Instant::now() >= *until {
                        let child = spawn(&exe, n.spec, &desc.env)?;
                        n.state = State::Running {
                            child,
                            since: Instant::now(),
                        };
                    }
                }
                State::Done => {}
            }
        }
        if !any_alive {
            log("every node has finished");
            return outcome(&failed);
        }
        std::thread::sleep(TICK);
    }
    stop_all(&mut nodes);
    outcome(&failed)
}
