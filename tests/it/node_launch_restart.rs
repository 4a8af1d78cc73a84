//! `rpkm launch` supervision: tcp_estimator is killed with SIGKILL mid-stream. The launcher
//! must restart it (new pid) without restarting ingest or preload_monitor; the restarted
//! estimator rejoins the stream (its estimates match the twin's true TCP again), and the
//! stream of the other nodes goes on without a gap: every ActuatorState reaches this test and
//! the monitor answers every sample.
#![expect(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use crate::node_support;

use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use node_support::{twin_stream, unique, write_truth_json, Launch, TempDir};
use rpkm_nodes::campaign_bag::stamp_from_seconds;
use rpkm_transport::{topic, Transport, TransportConfig};

const N: usize = 1200;
const RATE_HZ: f64 = 200.0;
/// Estimates received before the kill.
const KILL_AFTER: usize = 200;

#[test]
fn sigkilled_estimator_is_restarted_and_rejoins_while_the_stream_goes_on() {
    // its SIGKILLed node's resources are its own to see cleaned up (crate::KILLS_A_NODE)
    let _alone = crate::KILLS_A_NODE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let dir = TempDir::new("restart");
    let stream = twin_stream(N, RATE_HZ, |_| 0.0);
    let csv = dir.path("stream.csv");
    std::fs::write(&csv, stream.campaign.to_csv()).expect("write stream");
    let truth = dir.path("truth.json");
    write_truth_json(stream.twin.true_params(), &truth);
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    geometry_file: {}\n\
             ingest:\n  ros__parameters:\n    rate_hz: {RATE_HZ}\n    start_delay_s: 1.5\n\
             tcp_estimator:\n  ros__parameters:\n    busy_poll_ms: 0.0\n\
             preload_monitor:\n  ros__parameters:\n    status_every: 1\n    busy_poll_ms: 0.0\n",
            truth.display()
        ),
    )
    .expect("params");
    let launch = dir.path("restart.launch.yaml");
    std::fs::write(
        &launch,
        format!(
            "launch:\n  - node: {{pkg: rpkm, exec: ingest, param: [{{from: params.yaml}}], args: --source {}}}\n  \
             - node: {{pkg: rpkm, exec: tcp_estimator, param: [{{from: params.yaml}}], respawn: true, respawn_delay: 0.1}}\n  \
             - node: {{pkg: rpkm, exec: preload_monitor, param: [{{from: params.yaml}}]}}\n",
            csv.display()
        ),
    )
    .expect("launch file");

    let prefix = unique("restart");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let states = t.subscriber(&topic::ACTUATOR_STATE).expect("sub");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let statuses = t.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let by_stamp: HashMap<_, _> = stream
        .campaign
        .poses
        .iter()
        .enumerate()
        .filter_map(|(k, p)| Some((stamp_from_seconds(p.t)?, k)))
        .collect();

    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let mut state_seqs = Vec::new();
    let mut estimate_seqs = Vec::new();
    let mut status_samples = BTreeSet::new();
    let mut killed: Option<(u32, u64)> = None;
    let mut worst_error_m = 0.0f64;
    let deadline = Instant::now() + Duration::from_secs(90);
    while Instant::now() < deadline {
        let mut idle = true;
        while let Some(s) = states.try_recv().expect("recv") {
            idle = false;
            state_seqs.push(s.seq);
        }
        while let Some(s) = statuses.try_recv().expect("recv") {
            idle = false;
            status_samples.insert(*by_stamp.get(&s.stamp).expect("a stream stamp"));
        }
        while let Some(e) = estimates.try_recv().expect("recv") {
            idle = false;
            let k = *by_stamp.get(&e.stamp).expect("a stream stamp");
            assert_eq!(e.seq, k as u64 + 1, "seq echoes the state's");
            assert!(e.converged, "sample {k}");
            // Independent truth: the twin's true TCP (mm) of this sample.
            let tcp = stream.truth[k].tcp;
            let err = (e.x - tcp.x / 1e3).abs().max((e.y - tcp.y / 1e3).abs());
            worst_error_m = worst_error_m.max(err);
            estimate_seqs.push(e.seq);
        }
        if killed.is_none() && estimate_seqs.len() >= KILL_AFTER {
            let pids = launched.started("tcp_estimator");
            let pid = *pids.first().expect("estimator started");
            let ok = Command::new("kill")
                .args(["-KILL", &pid.to_string()])
                .status()
                .expect("kill");
            assert!(ok.success(), "SIGKILL {pid}");
            killed = Some((pid, *estimate_seqs.last().unwrap_or(&0)));
        }
        let done = state_seqs.last() == Some(&(N as u64))
            && status_samples.contains(&(N - 1))
            && estimate_seqs.last() == Some(&(N as u64));
        if done {
            break;
        }
        if idle {
            std::thread::sleep(Duration::from_micros(500));
        }
    }
    launched.stop();
    let (killed_pid, killed_at) = killed.expect("the estimator was killed");
    let estimators = launched.started("tcp_estimator");
    assert_eq!(estimators.len(), 2, "restarted once: {estimators:?}");
    assert_ne!(estimators[1], killed_pid);
    assert_eq!(launched.started("ingest").len(), 1, "ingest not restarted");
    assert_eq!(
        launched.started("preload_monitor").len(),
        1,
        "monitor not restarted"
    );
    assert_eq!(
        state_seqs,
        (1..=N as u64).collect::<Vec<_>>(),
        "the actuator stream went on without a gap"
    );
    assert_eq!(
        status_samples.len(),
        N,
        "the monitor answered every sample, also while the estimator was down"
    );
    let after: Vec<u64> = estimate_seqs
        .iter()
        .copied()
        .filter(|&s| s > killed_at)
        .collect();
    assert!(
        after.len() > N - killed_at as usize - (2.0 * RATE_HZ) as usize,
        "the restarted estimator rejoined within 2 s: {} estimates after seq {killed_at}",
        after.len()
    );
    // The killed process may have published a few more after `killed_at` was seen, so
    // `after` may start with its last ones: one gap (the downtime), then contiguous.
    let gaps: Vec<(u64, u64)> = after
        .windows(2)
        .filter(|w| w[1] != w[0] + 1)
        .map(|w| (w[0], w[1]))
        .collect();
    assert!(
        gaps.len() <= 1,
        "contiguous once rejoined; gaps after seq {killed_at}: {gaps:?}"
    );
    assert!(
        worst_error_m < 1e-9,
        "estimates match the twin's truth: {worst_error_m} m"
    );
}

/// The launch starts its nodes one at a time, each after the one before said its start-up
/// line. SIGTERM to `rpkm launch` (its tokio signal stream): SIGTERM to every node, each stops
/// cleanly (exit 0, not killed: the grace is 5 s), the launch exits 0, and no node process
/// is left (their pids are gone from /proc).
#[test]
fn sigterm_stops_every_node_cleanly_and_the_launch_exits_0() {
    let dir = TempDir::new("launch_term");
    let launch = dir.path("term.launch.yaml");
    std::fs::write(
        &launch,
        "launch:\n  - node: {pkg: rpkm, exec: tcp_estimator, respawn: true}\n  \
         - node: {pkg: rpkm, exec: preload_monitor}\n",
    )
    .expect("launch file");
    let prefix = unique("term");
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    // The nodes' own first lines, in whichever order: their signal handlers are installed
    // before them.
    let up = Instant::now() + Duration::from_secs(60);
    let logged = |needle: &str| {
        let log = launched.log.lock().expect("log");
        log.iter().any(|l| l.contains(needle))
    };
    while !(logged("[tcp_estimator] estimating with")
        && logged("[preload_monitor] monitoring with"))
    {
        assert!(Instant::now() < up, "the nodes did not start within 60 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    // One node at a time: preload_monitor starts only after the estimator's start-up line
    // (docs/nodes.md, "A Fast DDS participant running while the nodes start"), and the
    // launch says so.
    let order = {
        let log = launched.log.lock().expect("log");
        let at = |needle: &str| log.iter().position(|l| l.contains(needle));
        (
            at("[tcp_estimator] estimating with"),
            at("[launch] started preload_monitor pid "),
            at("[launch] tcp_estimator said its start-up line after "),
            at("[launch] starting 2 processes one at a time"),
        )
    };
    assert!(
        matches!(order, (Some(said), Some(next), Some(_), Some(_)) if said < next),
        "{order:?} in {:?}",
        launched.log.lock().expect("log")
    );
    let pids: Vec<u32> = ["tcp_estimator", "preload_monitor"]
        .iter()
        .flat_map(|n| launched.started(n))
        .collect();
    assert_eq!(pids.len(), 2, "one start each: {pids:?}");
    let term = Command::new("kill")
        .args(["-TERM", &launched.child.id().to_string()])
        .status()
        .expect("kill");
    assert!(term.success());
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = launched.child.try_wait().expect("wait") {
            break s;
        }
        assert!(
            Instant::now() < deadline,
            "rpkm launch did not exit within 30 s of SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(status.code(), Some(0), "launch exit status {status:?}");
    // Its stderr is read to the end on another thread: the last lines may still be on the way.
    let done = Instant::now() + Duration::from_secs(10);
    while !logged("[launch] preload_monitor exited") && Instant::now() < done {
        std::thread::sleep(Duration::from_millis(20));
    }
    for line in [
        "[launch] SIGTERM received",
        "[launch] tcp_estimator exited with code 0",
        "[launch] preload_monitor exited with code 0",
    ] {
        assert!(
            logged(line),
            "no line {line:?} in {:?}",
            launched.log.lock().expect("log")
        );
    }
    for pid in pids {
        assert!(
            !Path::new(&format!("/proc/{pid}")).exists(),
            "node pid {pid} still exists after the launch ended"
        );
    }
}

/// Two nodes SIGKILLed together restart one at a time: the second only after the first
/// restarted one said its start-up line (nodes announcing their first DDS endpoints together
/// are what a running Fast DDS participant may miss: docs/nodes.md).
#[test]
fn nodes_killed_together_restart_one_at_a_time() {
    let _alone = crate::KILLS_A_NODE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let dir = TempDir::new("launch_two");
    let launch = dir.path("two.launch.yaml");
    std::fs::write(
        &launch,
        "launch:\n  - node: {pkg: rpkm, exec: tcp_estimator, respawn: true, respawn_delay: 0.1}\n  \
         - node: {pkg: rpkm, exec: preload_monitor, respawn: true, respawn_delay: 0.1}\n",
    )
    .expect("launch file");
    let prefix = unique("two");
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let log = std::sync::Arc::clone(&launched.log);
    let lines = |needle: &str| {
        let log = log.lock().expect("log");
        log.iter()
            .enumerate()
            .filter(|(_, l)| l.contains(needle))
            .map(|(i, _)| i)
            .collect::<Vec<_>>()
    };
    let until = |what: &str, done: &dyn Fn() -> bool| {
        let deadline = Instant::now() + Duration::from_secs(60);
        while !done() {
            assert!(Instant::now() < deadline, "{what} not within 60 s");
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    until("both start-up lines", &|| {
        lines("said its start-up line after").len() == 2
    });
    let pids: Vec<String> = ["tcp_estimator", "preload_monitor"]
        .iter()
        .flat_map(|n| launched.started(n))
        .map(|p| p.to_string())
        .collect();
    assert_eq!(pids.len(), 2, "{pids:?}");
    let ok = Command::new("kill")
        .arg("-KILL")
        .args(&pids)
        .status()
        .expect("kill");
    assert!(ok.success(), "SIGKILL {pids:?}");
    until("both restarts", &|| lines("[launch] started ").len() == 4);
    // the first restarted one's start-up line, as the launch waited for it (10 s at most)
    let deadline = Instant::now() + Duration::from_secs(15);
    while lines("said its start-up line after").len() < 3 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    launched.stop();
    let started = lines("[launch] started ");
    let said = lines("said its start-up line after");
    // the first restarted node said its line before the second was started
    assert!(
        said.len() >= 3 && said[2] < started[3],
        "said {said:?}, started {started:?} in {:?}",
        log.lock().expect("log")
    );
}
