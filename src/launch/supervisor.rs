//! Starts the nodes of a launch description as processes of the node program beside this
//! binary (`rpkm-node <exec> --name <name> --params ...`, see `programs.rs`) and the
//! commands (`rpkm record`) as processes of this one, and supervises them:
//! - the nodes start one at a time, each once the one before has said its start-up line (at
//!   most 10 s; `ready.rs`), and so does a node restarted while another waits for its restart;
//! - a node that dies (non-zero exit or a signal) is restarted when `respawn` is on, after
//!   `respawn_delay` doubled for every crash within 10 s of its start (at most 5 s); exit
//!   code 0 (input done) and 2 (bad configuration: restarting cannot help) are final, and
//!   a node that exited 2 makes the launch exit 2 too, naming it; a node that ended 5 times
//!   in a row within 10 s of its start is not restarted either (the launch exits 1 at its
//!   end, naming it): what fails at every start is not cured by another;
//! - before the first start and after every death, the iceoryx2 resources of dead processes
//!   are removed (a SIGKILLed node leaves its shared memory behind);
//! - SIGINT/SIGTERM: SIGTERM to every node, SIGKILL after 5 s for those still running.
//!
//! One tokio select loop on a current-thread runtime waits for whichever comes first: a
//! signal (`tokio::signal`), a node's exit (`tokio::process`, reaped on SIGCHLD, no
//! polling), or the next restart time (`tokio::time`). Children are killed on drop, so an
//! error that ends the launch early leaves no node behind.
//!
//! Events go to stderr as `[launch] ...` lines: `started NAME pid PID`, `NAME said its
//! start-up line after S s`, `NAME pid PID exited ...`, `restarting NAME in S s`.

use std::future::Future;
use std::os::unix::process::ExitStatusExt;
use std::pin::Pin;
use std::process::ExitStatus;
use std::task::Poll;
use std::time::Duration;

use anyhow::Context;
use tokio::process::{Child, Command};
use tokio::signal::unix::{signal, Signal, SignalKind};
use tokio::time::Instant;

use super::description::{LaunchDescription, LaunchProgram, NodeSpec};
use super::programs::Programs;
use super::ready::{NodeStart, ReadyPipe, START_WAIT};

/// A node's crash within this time of its start doubles the next restart delay.
const QUICK_CRASH: Duration = Duration::from_secs(10);
/// Crashes in a row, each within [`QUICK_CRASH`] of its start, after which a node is not
/// restarted: one that never stays up fails for something a restart does not change (its
/// configuration, its host), and restarting it for ever would hide that.
const QUICK_CRASH_LIMIT: u32 = 5;
/// Largest restart delay.
const MAX_DELAY: Duration = Duration::from_secs(5);
/// Time the nodes get to stop after SIGTERM.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);

enum State {
    /// `pid` as it was at the start: tokio forgets it once the child is reaped.
    Running {
        child: Child,
        pid: u32,
        since: Instant,
    },
    Waiting {
        until: Instant,
    },
    Done,
}

struct Supervised<'a> {
    spec: &'a NodeSpec,
    state: State,
    quick_crashes: u32,
    /// How its last process ended (`exited with code 2`), once one did.
    last_exit: Option<(String, bool)>,
}

impl Supervised<'_> {
    /// Its state as the launch's /diagnostics status says it (`rpkm monitor` reads it).
    /// An executable (`rpkm record`) is marked so: it is no node and says nothing itself.
    fn state_text(&self) -> String {
        use crate::monitor::state::{DONE, EXECUTABLE, GONE};
        let state = match (&self.state, &self.last_exit) {
            (State::Running { .. }, _) => "running".to_owned(),
            (State::Waiting { .. }, _) => "restarting".to_owned(),
            (State::Done, Some((how, true))) => format!("{DONE}{how}"),
            (State::Done, Some((how, false))) => format!("{GONE}{how}"),
            (State::Done, None) => format!("{GONE}stopped"),
        };
        if self.spec.program == super::description::LaunchProgram::Command {
            state + EXECUTABLE
        } else {
            state
        }
    }
}

/// The launch's own status on /diagnostics (iceoryx2, the nodes' prefix): every declared node
/// and its state, so that `rpkm monitor` knows which nodes should be there and which are
/// gone, with their exit code. Without iceoryx2 the launch runs on, unreported.
struct Reporter {
    publisher: Option<rpkm_transport::Publisher<rpkm_msgs::DiagnosticArray>>,
    // after the publisher: dropped last
    _transport: Option<rpkm_transport::Transport>,
    /// `rpkm/launch`, or `<namespace>/launch`.
    status_name: String,
}

/// Period of the launch's status report.
const REPORT_PERIOD: Duration = Duration::from_secs(1);

impl Reporter {
    fn open(desc: &LaunchDescription) -> Self {
        let prefix = desc
            .env
            .iter()
            .rev()
            .find(|(k, _)| k == "RPKM_IPC_PREFIX")
            .map(|(_, v)| v.clone())
            .or_else(|| std::env::var("RPKM_IPC_PREFIX").ok())
            .unwrap_or_default();
        // the namespace of the nodes (the first one's): the status goes where they report
        let namespace = desc
            .nodes
            .iter()
            .find_map(|n| n.namespace.clone())
            .unwrap_or_else(|| rpkm_transport::NODE_NAMESPACE.to_owned());
        let opened = rpkm_transport::Names::new(&namespace, &[])
            .map_err(|e| e.to_string())
            .and_then(|names| {
                let config = rpkm_transport::TransportConfig::new(format!(
                    "rpkm_launch_status_{}",
                    std::process::id()
                ))
                .ipc_prefix(prefix)
                .names(names.clone());
                let t = rpkm_transport::Transport::new(&config).map_err(|e| e.to_string())?;
                let p = t
                    .publisher(&rpkm_transport::topic::DIAGNOSTICS)
                    .map_err(|e| e.to_string())?;
                Ok((
                    t,
                    p,
                    names.status_name(crate::monitor::state::LAUNCH_STATUS),
                ))
            });
        match opened {
            Ok((t, p, status_name)) => Self {
                publisher: Some(p),
                _transport: Some(t),
                status_name,
            },
            Err(e) => {
                log(format!("no launch status on /diagnostics: {e}"));
                Self {
                    publisher: None,
                    _transport: None,
                    status_name: String::new(),
                }
            }
        }
    }

    fn report(&self, nodes: &[Supervised<'_>]) {
        let Some(publisher) = &self.publisher else {
            return;
        };
        let values: Vec<(&str, String)> = nodes
            .iter()
            .map(|n| (n.spec.name.as_str(), n.state_text()))
            .collect();
        let gone = values
            .iter()
            .filter(|(_, s)| s.starts_with(crate::monitor::state::GONE))
            .count();
        let level = if gone > 0 { 2 } else { 0 };
        let message = format!("{} nodes declared, {gone} gone", values.len());
        let status = rpkm_nodes::node::status(level, &self.status_name, message, values);
        if let Err(e) = publisher.publish(&rpkm_nodes::node::diagnostic_array(status)) {
            log(format!("launch status not published: {e}"));
        }
    }
}

/// One `[launch]` line in one write: the nodes share this stderr, and a line written in
/// pieces would interleave with theirs.
fn log(msg: impl std::fmt::Display) {
    rpkm_nodes::node::log_line("launch", msg);
}

fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exited with code {c}"),
        (None, Some(s)) => format!("killed by signal {s}"),
        _ => "ended".into(),
    }
}

/// Starts `spec`, handing it `ready` when the launch waits for its start-up line.
fn spawn(
    programs: &Programs,
    spec: &NodeSpec,
    env: &[(String, String)],
    ready: Option<&ReadyPipe>,
) -> anyhow::Result<Child> {
    let (exe, argv) = programs.command(spec);
    let mut cmd = Command::new(exe);
    cmd.args(argv);
    if let Some(pipe) = ready {
        pipe.pass_to(&mut cmd);
    }
    cmd.envs(env.iter().map(|(k, v)| (k, v)));
    // A launch that ends on an error (or a panic) takes its nodes with it.
    cmd.kill_on_drop(true);
    let child = cmd
        .spawn()
        .with_context(|| format!("starting node {} ({})", spec.name, exe.display()))?;
    log(format!(
        "started {} pid {}",
        spec.name,
        child.id().unwrap_or_default()
    ));
    Ok(child)
}

/// What the launch says about a node's start it waited for.
fn say_start(name: &str, start: &NodeStart) {
    log(match start {
        NodeStart::Said(t) => format!(
            "{name} said its start-up line after {:.2} s",
            t.as_secs_f64()
        ),
        NodeStart::Ended => format!("{name} ended before its start-up line"),
        NodeStart::TimedOut => format!(
            "WARN: {name} said no start-up line within {} s: going on without it",
            START_WAIT.as_secs()
        ),
    });
}

/// Starts `spec` and, for a node, waits until it has said its start-up line (every endpoint
/// it opens at its start exists), it ended, or [`START_WAIT`] passed, so that no two nodes
/// announce their first DDS endpoints at the same time (docs/nodes.md, "A Fast DDS
/// participant running while the nodes start"). A command (`rpkm record`) says no start-up
/// line: it is not waited for. The state is the node's from its spawn on; with it the stop
/// signal that came during the wait, if one did.
async fn start_in_turn(
    programs: &Programs,
    spec: &NodeSpec,
    env: &[(String, String)],
    signals: &mut StopSignals,
) -> anyhow::Result<(State, Option<&'static str>)> {
    if spec.program != LaunchProgram::Node {
        return Ok((running(spawn(programs, spec, env, None)?), None));
    }
    let pipe = ReadyPipe::new().context("making the pipe for a node's start-up signal")?;
    let state = running(spawn(programs, spec, env, Some(&pipe))?);
    let stop = tokio::select! {
        start = pipe.wait() => {
            say_start(&spec.name, &start);
            None
        }
        name = signals.next() => Some(name),
    };
    Ok((state, stop))
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

/// SIGTERM to a running child.
fn terminate(child: &Child) {
    // `id()` is `None` once the child was reaped: then there is no process to signal, and
    // its pid may belong to another process already.
    if let Some(pid) = child.id().and_then(|p| libc::pid_t::try_from(p).ok()) {
        // SAFETY: kill(2) on the pid of our own child, which has not been reaped yet (tokio
        // reaps it only inside `wait`, which this task is not in), so the pid is still ours.
        unsafe {
            libc::kill(pid, libc::SIGTERM);
        }
    }
}

/// The nodes the launch gave up on, by why.
#[derive(Default)]
struct Failed {
    /// Exited 2: rejected their configuration.
    configuration: Vec<String>,
    /// Crashed [`QUICK_CRASH_LIMIT`] times in a row right after their start.
    crashing: Vec<String>,
}

/// What became of a node whose process ended.
fn reaped(n: &mut Supervised<'_>, status: ExitStatus, lived: Duration, failed: &mut Failed) {
    n.last_exit = Some((describe(status), status.code() == Some(0)));
    // Exit 2 is a configuration error: restarting cannot help, and the launch must say so
    // in its own exit code.
    if status.code() == Some(2) {
        log(format!(
            "{} rejected its configuration (exit 2, its lines above say why): not restarted",
            n.spec.name
        ));
        failed.configuration.push(n.spec.name.clone());
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
    if n.quick_crashes >= QUICK_CRASH_LIMIT {
        log(format!(
            "{} ended {} times in a row within {} s of its start (its lines above say why): \
             not restarted",
            n.spec.name,
            n.quick_crashes,
            QUICK_CRASH.as_secs()
        ));
        failed.crashing.push(n.spec.name.clone());
        n.state = State::Done;
        return;
    }
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
async fn stop_all(nodes: &mut [Supervised<'_>]) {
    log("stopping every node");
    for n in nodes.iter() {
        if let State::Running { child, .. } = &n.state {
            terminate(child);
        }
    }
    let deadline = Instant::now() + STOP_TIMEOUT;
    for n in nodes.iter_mut() {
        if let State::Running { child, .. } = &mut n.state {
            match tokio::time::timeout_at(deadline, child.wait()).await {
                Ok(Ok(status)) => log(format!("{} {}", n.spec.name, describe(status))),
                outcome => {
                    let why = match outcome {
                        Ok(Err(e)) => format!("could not be waited for ({e})"),
                        _ => format!("did not stop within {} s", STOP_TIMEOUT.as_secs()),
                    };
                    log(format!("{} {why}: SIGKILL", n.spec.name));
                    if let Err(e) = child.kill().await {
                        log(format!("{}: SIGKILL failed: {e}", n.spec.name));
                    }
                }
            }
        }
        n.state = State::Done;
    }
    cleanup_dead();
}

/// The launch's outcome: bad input (exit 2) when nodes rejected their configuration, an
/// error (exit 1) when nodes kept crashing at their start.
fn outcome(failed: &Failed) -> anyhow::Result<()> {
    if !failed.configuration.is_empty() {
        return Err(rpkm_nodes::error::bad_input(format!(
            "{} node(s) failed their configuration (exit 2, not restarted): {}",
            failed.configuration.len(),
            failed.configuration.join(", ")
        )));
    }
    if !failed.crashing.is_empty() {
        anyhow::bail!(
            "{} node(s) ended {QUICK_CRASH_LIMIT} times in a row right after their start \
             (not restarted): {}",
            failed.crashing.len(),
            failed.crashing.join(", ")
        );
    }
    Ok(())
}

/// What the select loop woke up for.
enum Event {
    /// SIGINT or SIGTERM, by name.
    Stop(&'static str),
    /// The node at this index ended (or could not be waited for).
    Exited(usize, std::io::Result<ExitStatus>),
    /// A waiting node's restart time came.
    RestartDue,
    /// Time for the launch's status report.
    Report,
    /// The managed nodes were brought up (or the bring-up stopped, and said why).
    BroughtUp,
}

/// SIGINT and SIGTERM as streams; registered before the first node starts.
struct StopSignals {
    interrupt: Signal,
    terminate: Signal,
}

impl StopSignals {
    fn new() -> anyhow::Result<Self> {
        Ok(Self {
            interrupt: signal(SignalKind::interrupt()).context("handling SIGINT")?,
            terminate: signal(SignalKind::terminate()).context("handling SIGTERM")?,
        })
    }

    async fn next(&mut self) -> &'static str {
        tokio::select! {
            _ = self.interrupt.recv() => "SIGINT",
            _ = self.terminate.recv() => "SIGTERM",
        }
    }
}

type ExitWait<'c> = Pin<Box<dyn Future<Output = std::io::Result<ExitStatus>> + Send + 'c>>;

/// The first of the running children to end; never, when none runs.
async fn first_exit(mut waits: Vec<(usize, ExitWait<'_>)>) -> (usize, std::io::Result<ExitStatus>) {
    std::future::poll_fn(|cx| {
        for (i, wait) in &mut waits {
            if let Poll::Ready(r) = wait.as_mut().poll(cx) {
                return Poll::Ready((*i, r));
            }
        }
        Poll::Pending
    })
    .await
}

/// Waits for the next signal, node exit or restart time. Cancel-safe: `Child::wait` and
/// `Signal::recv` lose nothing when another branch wins.
async fn next_event(
    nodes: &mut [Supervised<'_>],
    signals: &mut StopSignals,
    report_at: Instant,
) -> Event {
    let restart_at = nodes
        .iter()
        .filter_map(|n| match n.state {
            State::Waiting { until } => Some(until),
            _ => None,
        })
        .min();
    let waits: Vec<(usize, ExitWait<'_>)> = nodes
        .iter_mut()
        .enumerate()
        .filter_map(|(i, n)| match &mut n.state {
            State::Running { child, .. } => Some((i, Box::pin(child.wait()) as ExitWait<'_>)),
            _ => None,
        })
        .collect();
    let restart = async {
        match restart_at {
            Some(t) => tokio::time::sleep_until(t).await,
            None => std::future::pending().await,
        }
    };
    tokio::select! {
        name = signals.next() => Event::Stop(name),
        (i, r) = first_exit(waits) => Event::Exited(i, r),
        () = restart => Event::RestartDue,
        () = tokio::time::sleep_until(report_at) => Event::Report,
    }
}

/// The state of a node just started.
fn running(child: Child) -> State {
    State::Running {
        pid: child.id().unwrap_or_default(),
        child,
        since: Instant::now(),
    }
}

/// Restarts every waiting node whose time has come. One while another node waits for its
/// restart (due now or later: nodes that crashed together fall due microseconds apart) starts
/// in turn ([`start_in_turn`]), so that the other starts after its start-up line; one alone
/// starts at once: no other node announces its endpoints at the same time. The stop signal
/// that came during a wait, if one did.
async fn restart_due(
    nodes: &mut [Supervised<'_>],
    programs: &Programs,
    env: &[(String, String)],
    signals: &mut StopSignals,
) -> anyhow::Result<Option<&'static str>> {
    let now = Instant::now();
    let due: Vec<usize> = (0..nodes.len())
        .filter(|&i| matches!(nodes[i].state, State::Waiting { until } if until <= now))
        .collect();
    for i in due {
        let others_waiting = nodes
            .iter()
            .enumerate()
            .any(|(j, n)| j != i && matches!(n.state, State::Waiting { .. }));
        let n = &mut nodes[i];
        if !others_waiting {
            n.state = running(spawn(programs, n.spec, env, None)?);
            continue;
        }
        let (state, stop) = start_in_turn(programs, n.spec, env, signals).await?;
        n.state = state;
        if stop.is_some() {
            return Ok(stop);
        }
    }
    Ok(None)
}

/// Runs the description until SIGINT/SIGTERM or until every node is done; an error when a
/// node rejected its configuration.
pub fn run(desc: &LaunchDescription) -> anyhow::Result<()> {
    tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .build()
        .context("starting the launch's tokio runtime")?
        .block_on(supervise(desc))
}

/// The order the nodes start in: the file's, `ingest` last. It publishes the drive states the
/// others read, and a cell plays its states as soon as ingest answers it: started first, the
/// states it took before the estimator had started were never estimated.
fn start_order(specs: &[NodeSpec]) -> impl Iterator<Item = &NodeSpec> {
    let source = |s: &&NodeSpec| s.exec == "ingest";
    specs
        .iter()
        .filter(move |s| !source(s))
        .chain(specs.iter().filter(source))
}

async fn supervise(desc: &LaunchDescription) -> anyhow::Result<()> {
    let mut signals = StopSignals::new()?;
    let programs = Programs::beside(&std::env::current_exe().context("locating the rpkm binary")?);
    if let Some(note) = programs.missing_note() {
        log(note);
    }
    cleanup_dead();
    let reporter = Reporter::open(desc);
    log(format!(
        "starting {} processes one at a time, ingest last: each node once the one before has \
         said its start-up line (its DDS endpoints exist), at most {} s each",
        desc.nodes.len(),
        START_WAIT.as_secs()
    ));
    let mut nodes: Vec<Supervised<'_>> = Vec::new();
    let mut failed = Failed::default();
    for spec in start_order(&desc.nodes) {
        let (state, stop) = start_in_turn(&programs, spec, &desc.env, &mut signals).await?;
        nodes.push(Supervised {
            spec,
            state,
            quick_crashes: 0,
            last_exit: None,
        });
        if let Some(name) = stop {
            log(format!("{name} received while starting {}", spec.name));
            stop_all(&mut nodes).await;
            return outcome(&failed);
        }
    }
    // reported and supervised in the file's order, whatever order they started in
    nodes.sort_by_key(|n| desc.nodes.iter().position(|s| std::ptr::eq(s, n.spec)));
    let mut report_at = Instant::now();
    // the managed nodes configured and activated in file order, while the loop supervises
    let bring_up = super::managed::bring_up(desc);
    tokio::pin!(bring_up);
    let mut brought_up = false;
    loop {
        if nodes.iter().all(|n| matches!(n.state, State::Done)) {
            reporter.report(&nodes);
            log("every node has finished");
            return outcome(&failed);
        }
        let event = tokio::select! {
            e = next_event(&mut nodes, &mut signals, report_at) => e,
            () = &mut bring_up, if !brought_up => Event::BroughtUp,
        };
        match event {
            Event::BroughtUp => brought_up = true,
            Event::Report => {
                reporter.report(&nodes);
                report_at = Instant::now() + REPORT_PERIOD;
            }
            Event::Stop(name) => {
                log(format!("{name} received"));
                break;
            }
            Event::Exited(i, status) => {
                let n = &mut nodes[i];
                let State::Running { pid, since, .. } = n.state else {
                    continue;
                };
                let lived = since.elapsed();
                let status = status.with_context(|| format!("waiting for node {}", n.spec.name))?;
                log(format!("{} pid {pid} {}", n.spec.name, describe(status)));
                cleanup_dead();
                reaped(n, status, lived, &mut failed);
                reporter.report(&nodes);
            }
            Event::RestartDue => {
                if let Some(name) =
                    restart_due(&mut nodes, &programs, &desc.env, &mut signals).await?
                {
                    log(format!("{name} received while restarting"));
                    break;
                }
            }
        }
    }
    stop_all(&mut nodes).await;
    outcome(&failed)
}
