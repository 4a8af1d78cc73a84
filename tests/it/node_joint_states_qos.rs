//! Issue 51: nothing that matches nothing is "OK". An independent ros2_control cell on Eclipse
//! Cyclone DDS (tests/python/joint_states_peer.py --best-effort) publishes JointState best
//! effort; ingest's reader is reliable (the cell block's `joint_states_qos`, the
//! broadcaster's default), so DDS matches none of it and no state arrives. Ingest's
//! /diagnostics must WARN naming the mismatch (the writer, what it offers, what the reader
//! requests) and that the joint states are quiet, and count it
//! (`joint_states_incompatible_qos`).
//!
//! Needs the venv; without it SKIPPED, under RPKM_REQUIRE_PYTHON=1 a failure.

use crate::joint_states_support::{cell, cell_block, joint_line, value, write_script, Observer};
use crate::node_support::{python, rpkm, twin_stream, unique, Proc, TempDir};

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use rpkm_msgs::DiagnosticStatus;
use rpkm_nodes::campaign_bag::stamp_from_seconds;

const DOMAIN: &str = "68";

/// Three seconds of the twin as the cell's JointStates at 1 kHz, no MATCH (none will).
fn cell_script(dir: &TempDir) -> std::path::PathBuf {
    let cell = cell();
    let twin = twin_stream(3000, 1000.0, |_| 0.0);
    let mut script = String::new();
    for pose in &twin.campaign.poses {
        let stamp = stamp_from_seconds(pose.t).expect("a stamp");
        let q = pose.q.map(|q| q / rpkm_nodes::units::MM_PER_M);
        script.push_str(&joint_line(&cell, stamp, q, pose.f));
    }
    write_script(&dir.0, &script)
}

#[test]
fn a_best_effort_cell_against_a_reliable_reader_is_named_on_diagnostics() {
    let Some(py) = python() else { return };
    let dir = TempDir::new("jsqos");
    let cell_yaml = dir.path("cell.yaml");
    std::fs::write(&cell_yaml, cell_block()).expect("cell.yaml");
    let prefix = unique("jsqos");
    let mut obs = Observer::new(&prefix, None);
    let _ingest = Proc(
        Command::new(rpkm())
            .args([
                "node",
                "ingest",
                "--source",
                "joint_states",
                "--backend",
                "ipc",
            ])
            .arg("--params")
            .arg(&cell_yaml)
            .args(["--param", "diagnostics_period_s=0.2"])
            .env("RPKM_IPC_PREFIX", &prefix)
            .env("ROS_DOMAIN_ID", DOMAIN)
            .spawn()
            .expect("start ingest"),
    );
    let script = cell_script(&dir);
    let started = Instant::now();
    let _cell = Proc(
        Command::new(&py)
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/joint_states_peer.py"))
            .arg(&script)
            .args(["--domain", DOMAIN, "--timeout", "30", "--best-effort"])
            .spawn()
            .expect("start the cell"),
    );
    let named = |s: &crate::joint_states_support::Observed| {
        s.diagnostics
            .get("rpkm/ingest")
            .is_some_and(|d| value(d, "joint_states_incompatible_qos") == Some("1"))
    };
    obs.until(Duration::from_secs(20), named);
    eprintln!(
        "the mismatch named on /diagnostics {:.2} s after the cell started",
        started.elapsed().as_secs_f64()
    );
    obs.until(Duration::from_secs(20), |s| {
        s.diagnostics
            .get("rpkm/ingest")
            .is_some_and(|d| value(d, "joint_states_quiet") == Some("true"))
    });
    let ingest = &obs.seen.diagnostics["rpkm/ingest"];
    eprintln!(
        "ingest /diagnostics: {} {:?}",
        ingest.message, ingest.values
    );
    assert_eq!(
        value(ingest, "joint_states_incompatible_qos"),
        Some("1"),
        "{}",
        ingest.message
    );
    assert_eq!(ingest.level, DiagnosticStatus::WARN);
    for needle in [
        "1 publisher(s) of /joint_states not matched, incompatible QoS",
        "offers best_effort volatile, this reader requests reliable volatile",
        "joint states quiet for",
    ] {
        assert!(
            ingest.message.contains(needle),
            "{needle:?}: {}",
            ingest.message
        );
    }
    assert_eq!(value(ingest, "joint_states_received"), Some("0"));
    assert_eq!(value(ingest, "joint_states_quiet"), Some("true"));
    assert!(
        obs.seen.states.is_empty(),
        "nothing arrived, nothing published"
    );
}
