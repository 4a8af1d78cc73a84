//! `ingest` accepts ActuatorState published by an independent DDS implementation: Eclipse
//! Cyclone DDS (tests/python/cyclone_peer.py, PyPI `cyclonedds`) publishes seq 1..N on
//! /rpkm/controller/actuator_state, then a NaN sample, an out-of-range one and the last good
//! one again, every 50 ms, each round's seqs following on from the last round's. Ingest must
//! republish every good sample from the first it saw, each once, none missing, with the
//! values Cyclone sent (bit for bit), and count the NaN, the out-of-range and the repeated
//! (out-of-order) samples on /diagnostics. Where the first round begins for ingest is up to
//! DDS discovery; that is why the rounds do not repeat their seqs.
//!
//! The venv: `python3 -m venv .venv && .venv/bin/pip install -r tests/python/requirements.txt`
//! in the repository root; without it the test prints SKIPPED, and under
//! RPKM_REQUIRE_PYTHON=1 (`.ci/run`) it fails instead.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use crate::node_support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use node_support::{python, rpkm, unique, Proc};
use rpkm_msgs::{ActuatorState, Time};
use rpkm_transport::{topic, Transport, TransportConfig};

const COUNT: u64 = 10;
const DOMAIN: &str = "58";

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
        follower: [false, !seq.is_multiple_of(2), seq.is_multiple_of(3), false],
        covariate_count: 2,
        covariates: [21.5 + s, 22.25, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    }
}

/// The good seqs from `first` on: a round is COUNT good seqs, then a NaN one and an
/// out-of-range one (see cyclone_peer.py --fresh-rounds).
fn good_seqs(first: u64) -> impl Iterator<Item = u64> {
    (first..).filter(|seq| (seq - 1) % (COUNT + 2) < COUNT)
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn ingest_accepts_cyclone_actuator_states_and_counts_the_bad_ones() {
    let Some(py) = python() else { return };
    let prefix = unique("cyc");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let states = t.subscriber(&topic::ACTUATOR_STATE).expect("sub");
    let diagnostics = t.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let _ingest = Proc(
        Command::new(rpkm())
            .args(["node", "ingest", "--source", "dds", "--backend", "ipc"])
            .args([
                "--param",
                "start_delay_s=0",
                "--param",
                "diagnostics_period_s=0.2",
            ])
            .env("RPKM_IPC_PREFIX", &prefix)
            .env("ROS_DOMAIN_ID", DOMAIN)
            .spawn()
            .expect("start ingest"),
    );
    // Let ingest's DDS reader exist before Cyclone writes. Its first /diagnostics comes from
    // the loop that reads DDS, after the reader was made. (A reader that learns of Cyclone's
    // writer mid-round still sees every later sample: the rounds do not repeat seqs.)
    let up = Instant::now() + Duration::from_secs(30);
    let mut ready = false;
    while !ready && Instant::now() < up {
        ready = diagnostics
            .recv_timeout(Duration::from_millis(100))
            .expect("recv")
            .is_some_and(|d| d.status.iter().any(|s| s.name == "rpkm/ingest"));
    }
    assert!(ready, "ingest did not report on /diagnostics within 30 s");
    let _peer = Proc(
        Command::new(py)
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/cyclone_peer.py"))
            .args([
                "pub_actuator",
                "--domain",
                DOMAIN,
                "--count",
                &COUNT.to_string(),
            ])
            .args([
                "--topic",
                "/rpkm/controller/actuator_state",
                "--bad",
                "--fresh-rounds",
                "--timeout",
                "30",
            ])
            .stdout(Stdio::null())
            .spawn()
            .expect("start cyclone_peer.py"),
    );
    let mut received = Vec::new();
    let mut counts = (0u64, 0u64, 0u64);
    let value = |s: &rpkm_msgs::DiagnosticStatus, key: &str| -> u64 {
        s.values
            .iter()
            .find(|v| v.key == key)
            .and_then(|v| v.value.parse().ok())
            .unwrap_or(0)
    };
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        while let Some(s) = states.try_recv().expect("recv") {
            received.push(s);
        }
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            for s in d.status.iter().filter(|s| s.name == "rpkm/ingest") {
                counts = (
                    value(s, "rejected_non_finite"),
                    value(s, "rejected_out_of_range"),
                    value(s, "rejected_out_of_order"),
                );
            }
        }
        if received.len() >= COUNT as usize && counts.0 > 0 && counts.1 > 0 && counts.2 > 0 {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    received.truncate(COUNT as usize);
    let seqs: Vec<u64> = received.iter().map(|s| s.seq).collect();
    let first = seqs.first().copied().unwrap_or(0);
    let last = first + COUNT - 1;
    assert_eq!(
        seqs,
        good_seqs(first).take(COUNT as usize).collect::<Vec<_>>(),
        "each good sample once, none missing, from the first ingest saw to {last}"
    );
    for s in &received {
        let e = expected_actuator(s.seq);
        assert_eq!(s.stamp, e.stamp);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&s.position), bits(&e.position), "seq {}", s.seq);
        assert_eq!(bits(&s.force), bits(&e.force), "seq {}", s.seq);
        assert_eq!(bits(&s.covariates), bits(&e.covariates), "seq {}", s.seq);
        assert_eq!(s.follower, e.follower);
        assert_eq!(s.covariate_count, e.covariate_count);
    }
    assert!(counts.0 >= 1, "the NaN sample is counted: {counts:?}");
    assert!(
        counts.1 >= 1,
        "the out-of-range sample is counted: {counts:?}"
    );
    assert!(
        counts.2 >= 1,
        "the repeated rounds are out of order: {counts:?}"
    );
}
