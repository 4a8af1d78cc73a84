//! tcp_estimator as a managed node, driven by an independent lifecycle client (Eclipse
//! Cyclone DDS, tests/python/lifecycle_peer.py, the types of ROS 2's lifecycle_msgs):
//! started `--unconfigured`, it goes configure → activate → deactivate → cleanup → shutdown,
//! each change answered `success`, `~/get_state` and `~/get_available_transitions` right
//! after each, every transition seen on `~/transition_event` (its start through the
//! transition state, then its end), and its estimates only while active: none reaches the
//! client before the activate request, none of a drive state sent after the node became
//! inactive again. Drive states stream over iceoryx2 all along, stamped with the wall clock
//! that the events' timestamps use too.
//!
//! ingest alike, on a campaign file: started `--unconfigured`, no drive state reaches the
//! client before the activate request, states stream while it is active, and none is
//! received later than a quarter of a second (delivery) after the node became inactive: the
//! file waits where it is.
//!
//! Needs the venv; without it SKIPPED, under RPKM_REQUIRE_PYTHON=1 a failure.

use crate::node_support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use node_support::{python, rpkm, unique, Proc};
use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::{ActuatorState, Time};
use rpkm_transport::{topic, Transport, TransportConfig};
use serde_json::{json, Value};

const DOMAIN: &str = "77";
const DOMAIN_INGEST: &str = "80";

/// Runs the lifecycle peer on `node` through configure, activate, deactivate, cleanup,
/// shutdown (1.5 s in each state), watching `watch`; its report, checked for the answers and
/// the ten events.
fn drive(py: &Path, domain: &str, node: &str, watch: &str) -> (Value, String) {
    let peer = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/lifecycle_peer.py");
    let out = Command::new(py)
        .arg(peer)
        .args(["--domain", domain, "--node", node, "--dwell", "1.5"])
        .args(["--watch", watch])
        .args(["configure", "activate", "deactivate", "cleanup", "shutdown"])
        .stderr(Stdio::inherit())
        .output()
        .expect("run the peer");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "peer: {text}");
    let report: Value = serde_json::from_str(text.trim()).expect("JSON report");
    assert_eq!(report["initial_state"], 1, "{text}");
    // (transition, success, state after, transitions offered there)
    let steps: Vec<Value> = report["steps"].as_array().expect("steps").clone();
    assert_eq!(
        steps,
        [
            json!({"transition": "configure", "success": true, "state": 2, "offered": [2, 3, 6]}),
            json!({"transition": "activate", "success": true, "state": 3, "offered": [4, 7]}),
            json!({"transition": "deactivate", "success": true, "state": 2, "offered": [2, 3, 6]}),
            json!({"transition": "cleanup", "success": true, "state": 1, "offered": [1, 5]}),
            json!({"transition": "shutdown", "success": true, "state": 4, "offered": []}),
        ],
        "{text}"
    );
    check_events(report["events"].as_array().expect("events"), &text);
    assert_eq!(report["estimates_before_activate"], 0, "{text}");
    (report, text)
}

/// Wall-clock now as a message stamp, and in ns.
fn now() -> (Time, u64) {
    let d = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("after 1970");
    let t = Time {
        sec: i32::try_from(d.as_secs()).expect("before 2038"),
        nanosec: d.subsec_nanos(),
    };
    (t, u64::try_from(d.as_nanos()).expect("ns fit"))
}

#[test]
fn a_lifecycle_client_drives_the_estimator_through_every_transition() {
    let Some(py) = python() else { return };
    let prefix = unique("life");
    let t = Transport::new(&TransportConfig::new(unique("lifeobs")).ipc_prefix(&prefix))
        .expect("transport");
    let states = t.publisher(&topic::ACTUATOR_STATE).expect("publisher");
    let _node = Proc(
        Command::new(rpkm())
            .args([
                "node",
                "tcp_estimator",
                "--unconfigured",
                "--backend",
                "both",
            ])
            .args(["--input-backend", "ipc", "--ipc-prefix", &prefix])
            .env("ROS_DOMAIN_ID", DOMAIN)
            .spawn()
            .expect("start tcp_estimator"),
    );
    let done = Arc::new(AtomicBool::new(false));
    let streaming = stream(states, Arc::clone(&done));
    let (report, _) = drive(&py, DOMAIN, "/rpkm/tcp_estimator", "tcp_estimate");
    done.store(true, Ordering::Relaxed);
    streaming.join().expect("streaming thread");
    let events = report["events"].as_array().expect("events");
    // the node became inactive at the end of deactivating; no state sent after it was
    // estimated
    let inactive_at = events[5]["timestamp"].as_u64().expect("timestamp");
    let stamps: Vec<u64> = report["estimate_stamps"]
        .as_array()
        .expect("stamps")
        .iter()
        .filter_map(Value::as_u64)
        .collect();
    let while_active = stamps.iter().filter(|&&s| s < inactive_at).count();
    assert!(while_active > 20, "{while_active} estimates while active");
    let late = stamps.iter().filter(|&&s| s > inactive_at).count();
    assert_eq!(
        late, 0,
        "estimates of states sent after the node became inactive"
    );
}

#[test]
fn a_lifecycle_client_drives_ingest_through_every_transition() {
    let Some(py) = python() else { return };
    let campaign = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/demo/campaign.csv");
    let _node = Proc(
        Command::new(rpkm())
            .args(["node", "ingest", "--unconfigured", "--backend", "dds"])
            .arg("--source")
            .arg(&campaign)
            // 194 poses at 40 Hz: about 5 s, longer than the 1.5 s the node is active
            .args(["--param", "rate_hz=40", "--param", "start_delay_s=0"])
            .env("ROS_DOMAIN_ID", DOMAIN_INGEST)
            .spawn()
            .expect("start ingest"),
    );
    let (report, text) = drive(&py, DOMAIN_INGEST, "/rpkm/ingest", "actuator_state");
    let events = report["events"].as_array().expect("events");
    let inactive_at = events[5]["timestamp"].as_u64().expect("timestamp");
    let received: Vec<u64> = report["received_ns"]
        .as_array()
        .expect("received")
        .iter()
        .filter_map(Value::as_u64)
        .collect();
    let while_active = received.iter().filter(|&&t| t < inactive_at).count();
    assert!(
        while_active > 20,
        "{while_active} states while active: {text}"
    );
    // a state published before the node became inactive may still be on its way
    let late = received
        .iter()
        .filter(|&&t| t > inactive_at + 250_000_000)
        .count();
    assert_eq!(
        late, 0,
        "states received after the node became inactive: {text}"
    );
    eprintln!(
        "ingest: {while_active} drive states while active, {} in all",
        received.len()
    );
}

/// Drive states at 200 Hz, stamped with the wall clock, until `done`.
fn stream(
    states: rpkm_transport::Publisher<ActuatorState>,
    done: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let q = igm(&Params::nominal(), Model::M29, 0.0, 1500.0)
            .expect("igm")
            .q();
        let mut seq = 0;
        while !done.load(Ordering::Relaxed) {
            seq += 1;
            let state = ActuatorState {
                stamp: now().0,
                seq,
                position: q.map(|v| v * 1e-3),
                follower: [false, true, true, false],
                ..ActuatorState::default()
            };
            states.publish(&state).expect("publish state");
            std::thread::sleep(Duration::from_millis(5));
        }
    })
}

/// The ten transition events, in order: each transition's start into its transition state,
/// then its end.
fn check_events(events: &[Value], text: &str) {
    let seen: Vec<(u64, String, u64, u64)> = events
        .iter()
        .map(|e| {
            (
                e["transition"][0].as_u64().expect("id"),
                e["transition"][1].as_str().expect("label").to_owned(),
                e["start"].as_u64().expect("start"),
                e["goal"].as_u64().expect("goal"),
            )
        })
        .collect();
    let want: Vec<(u64, String, u64, u64)> = [
        (1, "configure", 1, 10),
        (10, "transition_success", 10, 2),
        (3, "activate", 2, 13),
        (30, "transition_success", 13, 3),
        (4, "deactivate", 3, 14),
        (40, "transition_success", 14, 2),
        (2, "cleanup", 2, 11),
        (20, "transition_success", 11, 1),
        (5, "shutdown", 1, 12),
        (50, "transition_success", 12, 4),
    ]
    .into_iter()
    .map(|(i, l, s, g)| (i, l.to_owned(), s, g))
    .collect();
    assert_eq!(seen, want, "{text}");
}
