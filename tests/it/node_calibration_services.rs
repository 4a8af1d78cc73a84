//! `~/load_calibration` and `~/save_calibration` on a running tcp_estimator, called by an
//! independent client (Eclipse Cyclone DDS, tests/python/calibration_service_peer.py, the
//! types of msgs/srv/*.srv): after a load, the next estimate of a drive state is the core's
//! rigid fgm of the loaded geometry (follower mode, no drive force: the elastic estimate is
//! the rigid pose), no longer the nominal one's; a save writes the geometry the node holds,
//! which reads back as the loaded parameters.
//!
//! Needs the venv (`python3 -m venv .venv && .venv/bin/pip install -r
//! tests/python/requirements.txt`); without it SKIPPED, under RPKM_REQUIRE_PYTHON=1 a failure.

use crate::node_support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use node_support::{python, rpkm, unique, Proc, TempDir};
use rpkm_core::geometry::{fgm, igm};
use rpkm_core::params::{index_of, Model, Params};
use rpkm_msgs::{ActuatorState, TcpEstimate, Time};
use rpkm_transport::{topic, Publisher, Subscriber, Transport, TransportConfig};

const DOMAIN: &str = "76";

/// A drive state of pose (x, y) mm of the nominal machine, q2 and q3 followers, no force.
fn state(seq: u64) -> ActuatorState {
    let q = igm(&Params::nominal(), Model::M29, 40.0, 1500.0)
        .expect("igm")
        .q();
    ActuatorState {
        stamp: Time {
            sec: 1000,
            nanosec: u32::try_from(seq).expect("small seq"),
        },
        seq,
        position: q.map(|v| v * 1e-3),
        follower: [false, true, true, false],
        ..ActuatorState::default()
    }
}

/// Publishes states until an estimate of one comes back; its (x, y) in mm.
fn estimate(
    states: &Publisher<ActuatorState>,
    estimates: &Subscriber<TcpEstimate>,
    seq: &mut u64,
) -> (f64, f64) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        *seq += 1;
        states.publish(&state(*seq)).expect("publish state");
        if let Some(e) = estimates
            .recv_timeout(Duration::from_millis(200))
            .expect("receive")
        {
            // only an estimate of the state just sent: the geometry at that time
            if e.seq == *seq {
                return (e.x * 1e3, e.y * 1e3);
            }
        }
    }
    panic!("no estimate within 30 s");
}

/// Calls `service` of the estimator with `path`; the reply's (success, message).
fn call(py: &Path, service: &str, path: &Path) -> (bool, String) {
    let peer =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/calibration_service_peer.py");
    let out = Command::new(py)
        .arg(peer)
        .args(["--domain", DOMAIN, "--node", "/rpkm/tcp_estimator"])
        .args(["--service", service, "--path"])
        .arg(path)
        .args(["--timeout", "60"])
        .stderr(Stdio::inherit())
        .output()
        .expect("run the peer");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer: {text}");
    let reply: serde_json::Value = serde_json::from_str(text.trim()).expect("JSON reply");
    (
        reply["success"].as_bool().expect("success"),
        reply["message"].as_str().unwrap_or_default().to_owned(),
    )
}

#[test]
fn load_calibration_changes_the_next_estimate_to_the_loaded_geometry() {
    let Some(py) = python() else { return };
    let dir = TempDir::new("calsrv");
    // a geometry a few millimetres off the drawing: rods 1 and 4 longer, guide 1 tilted
    let mut loaded = Params::nominal();
    for (name, delta) in [("l1", 2.0), ("l4", -1.5), ("gamma1", 0.002)] {
        loaded[index_of(name).expect("a parameter")] += delta;
    }
    let file = dir.path("cal.json");
    let parameters: serde_json::Map<String, serde_json::Value> = rpkm_core::params::NAMES
        .iter()
        .enumerate()
        .map(|(i, n)| ((*n).to_owned(), serde_json::Value::from(loaded[i])))
        .collect();
    std::fs::write(
        &file,
        serde_json::json!({ "parameters": parameters }).to_string(),
    )
    .expect("write calibration");
    let prefix = unique("calsrv");
    let t = Transport::new(&TransportConfig::new(unique("calobs")).ipc_prefix(&prefix))
        .expect("transport");
    let states = t.publisher(&topic::ACTUATOR_STATE).expect("publisher");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("subscriber");
    let _node = Proc(
        Command::new(rpkm())
            .args([
                "node",
                "tcp_estimator",
                "--backend",
                "both",
                "--input-backend",
                "ipc",
            ])
            .args(["--ipc-prefix", &prefix])
            .env("ROS_DOMAIN_ID", DOMAIN)
            .spawn()
            .expect("start tcp_estimator"),
    );
    let q = state(0).position.map(|v| v * 1e3);
    let rigid = |p: &Params| {
        let r = fgm(p, Model::M29, q[0], q[3]).expect("fgm");
        (r.x(), r.y())
    };
    let (nominal, wanted) = (rigid(&Params::nominal()), rigid(&loaded));
    let apart = (nominal.0 - wanted.0).hypot(nominal.1 - wanted.1);
    assert!(
        apart > 0.5,
        "the two geometries put the TCP {apart} mm apart"
    );
    let mut seq = 0;
    let before = estimate(&states, &estimates, &mut seq);
    let off = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
    assert!(
        off(before, nominal) < 1e-3,
        "{before:?} vs nominal {nominal:?}"
    );
    let (ok, message) = call(&py, "load_calibration", &file);
    assert!(ok, "{message}");
    assert!(message.contains("cal.json"), "{message}");
    let after = estimate(&states, &estimates, &mut seq);
    assert!(
        off(after, wanted) < 1e-3,
        "{after:?} vs the loaded geometry's {wanted:?} (nominal {nominal:?})"
    );
    // the save writes what the node holds: the loaded parameters
    let saved = dir.path("saved.json");
    let (ok, message) = call(&py, "save_calibration", &saved);
    assert!(ok, "{message}");
    let back = rpkm_nodes::input::read_params(&saved).expect("the saved file reads back");
    let worst = (0..rpkm_core::params::N_PARAMS)
        .map(|i| (back[i] - loaded[i]).abs())
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-12, "saved parameters differ by {worst}");
    // a file that is not there: refused with its name, the geometry stays
    let (ok, message) = call(&py, "load_calibration", &dir.path("missing.json"));
    assert!(!ok && message.contains("missing.json"), "{message}");
    let still = estimate(&states, &estimates, &mut seq);
    assert!(off(still, wanted) < 1e-3, "{still:?}");
}
