//! DDS interoperability with an independent implementation: Eclipse Cyclone DDS through
//! tests/python/cyclone_peer.py (PyPI `cyclonedds`), run with /work/main/.venv/bin/python.
//! (a) Cyclone subscribes to /rpkm/tcp_estimate that we publish; (b) Cyclone publishes
//! /rpkm/actuator_state that we receive. Values are compared exactly (float64 bit patterns).
//!
//! The venv: `python3 -m venv .venv && .venv/bin/pip install cyclonedds` in the repository
//! root. Without it the tests print a message and pass without running.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::time::{Duration, Instant};

use rpkm_msgs::{ActuatorState, TcpEstimate, Time};
use rpkm_transport::{topic, Backend, Transport, TransportConfig};

const COUNT: u64 = 10;
const TIMEOUT: Duration = Duration::from_secs(30);

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The venv's python, or `None` (with a message) if the venv is absent.
fn python() -> Option<PathBuf> {
    let py = repo_root().join(".venv/bin/python");
    if py.exists() {
        Some(py)
    } else {
        // CI (.ci/run) installs the venv and sets RPKM_REQUIRE_PYTHON: there a skip is a failure.
        assert!(
            std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
            "RPKM_REQUIRE_PYTHON is set but {} is missing",
            py.display()
        );
        eprintln!(
            "SKIPPED: {} not found; create it with `python3 -m venv .venv && \
             .venv/bin/pip install cyclonedds` in the repository root",
            py.display()
        );
        None
    }
}

/// Kills the peer when the test ends, also on panic.
struct Peer {
    child: Child,
    lines: Receiver<String>,
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn spawn_peer(py: &Path, mode: &str, domain: u16) -> Peer {
    let mut child = Command::new(py)
        .arg(repo_root().join("tests/python/cyclone_peer.py"))
        .args([
            mode,
            "--domain",
            &domain.to_string(),
            "--count",
            &COUNT.to_string(),
        ])
        .args(["--timeout", &TIMEOUT.as_secs().to_string()])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {} cyclone_peer.py: {e}", py.display()));
    let stdout = child.stdout.take().expect("piped stdout");
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let peer = Peer { child, lines };
    let first = peer.lines.recv_timeout(TIMEOUT).unwrap_or_else(|_| {
        panic!("cyclone_peer.py {mode} did not print READY within {TIMEOUT:?}")
    });
    assert_eq!(first, "READY", "cyclone_peer.py {mode} started badly");
    peer
}

/// Same formula as `expected_estimate` in cyclone_peer.py.
fn expected_estimate(seq: u64) -> TcpEstimate {
    let s = seq as f64;
    TcpEstimate {
        stamp: Time {
            sec: 1000 + seq as i32,
            nanosec: seq as u32 * 1000,
        },
        seq,
        x: s * 1e-3,
        y: 1.7 + s * 1e-4,
        psi: -s * 1e-6,
        loop_residuals: [s * 1e-9, 2e-9, 3e-9, 4e-9, 0.0],
        rod_forces: [s, -s, 100.0, -100.0, 0.5],
        drive_forces: [1.0, 2.0, -3.0, s],
        iterations: seq as u32 + 2,
        model: 29,
        converged: seq.is_multiple_of(2),
        outcome: (seq % 3) as u8,
        reason: (seq % 7) as u8,
    }
}

/// Same formula as `expected_actuator` in cyclone_peer.py.
fn expected_actuator(seq: u64) -> ActuatorState {
    let s = seq as f64;
    ActuatorState {
        stamp: Time {
            sec: 2000 + seq as i32,
            nanosec: 7 * seq as u32,
        },
        seq,
        position: [
            2.611_055_6 + s * 1e-6,
            2.611_055_6,
            0.788_944_4,
            0.788_944_4 - s * 1e-6,
        ],
        force: [s, -2.0 * s, 0.0, 8600.0],
        follower: [false, seq % 2 == 1, seq.is_multiple_of(3), false],
        covariate_count: 2,
        covariates: [21.5 + s, 22.25, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    }
}

/// The JSON form cyclone_peer.py prints: float64s as bit patterns.
fn estimate_json(m: &TcpEstimate) -> serde_json::Value {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    serde_json::json!({
        "stamp": [m.stamp.sec, m.stamp.nanosec],
        "seq": m.seq,
        "x": m.x.to_bits(),
        "y": m.y.to_bits(),
        "psi": m.psi.to_bits(),
        "loop_residuals": bits(&m.loop_residuals),
        "rod_forces": bits(&m.rod_forces),
        "drive_forces": bits(&m.drive_forces),
        "iterations": m.iterations,
        "model": m.model,
        "converged": m.converged,
        "outcome": m.outcome,
        "reason": m.reason,
    })
}

fn dds(name: &str, domain: u16) -> Transport {
    Transport::new(
        &TransportConfig::new(name)
            .backend(Backend::Dds)
            .dds_domain(domain),
    )
    .expect("DDS transport")
}

#[test]
fn cyclone_receives_our_tcp_estimates() {
    let Some(py) = python() else { return };
    let peer = spawn_peer(&py, "sub_estimate", 58);
    let transport = dds("interop_tx", 58);
    let publisher = transport
        .publisher(&topic::TCP_ESTIMATE)
        .expect("publisher");

    let start = Instant::now();
    let mut received = Vec::new();
    'outer: loop {
        assert!(
            start.elapsed() < TIMEOUT,
            "Cyclone did not report all {COUNT} TcpEstimates within {TIMEOUT:?}; got {received:?}"
        );
        for seq in 1..=COUNT {
            publisher.publish(&expected_estimate(seq)).expect("publish");
        }
        while let Ok(line) = peer.lines.recv_timeout(Duration::from_millis(20)) {
            match line.as_str() {
                "DONE" => break 'outer,
                l if l.starts_with("MISMATCH") || l.starts_with("TIMEOUT") => {
                    panic!("cyclone_peer.py: {l}")
                }
                l => received.push(
                    serde_json::from_str::<serde_json::Value>(l)
                        .unwrap_or_else(|e| panic!("bad line from cyclone_peer.py {l:?}: {e}")),
                ),
            }
        }
    }
    assert_eq!(received.len() as u64, COUNT);
    for v in &received {
        let seq = v["seq"].as_u64().unwrap_or_else(|| panic!("no seq in {v}"));
        assert_eq!(
            *v,
            estimate_json(&expected_estimate(seq)),
            "TcpEstimate seq {seq}"
        );
    }
}

#[test]
fn we_receive_cyclone_actuator_states() {
    let Some(py) = python() else { return };
    let transport = dds("interop_rx", 59);
    let subscriber = transport
        .subscriber(&topic::ACTUATOR_STATE)
        .expect("subscriber");
    let _peer = spawn_peer(&py, "pub_actuator", 59);

    let start = Instant::now();
    let mut seen = std::collections::BTreeSet::new();
    while (seen.len() as u64) < COUNT {
        let left = TIMEOUT.saturating_sub(start.elapsed());
        let msg = subscriber
            .recv_timeout(left)
            .expect("receive")
            .unwrap_or_else(|| {
                panic!("only ActuatorState seq {seen:?} of 1..={COUNT} from Cyclone within {TIMEOUT:?}")
            });
        assert_eq!(
            msg,
            expected_actuator(msg.seq),
            "ActuatorState seq {}",
            msg.seq
        );
        seen.insert(msg.seq);
    }
}
