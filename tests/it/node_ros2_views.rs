//! The standard views of a running cell, checked by an independent DDS peer: Eclipse Cyclone
//! DDS (tests/python/ros2_views_peer.py, types from the ROS 2 .msg files) receives
//! `geometry_msgs/PoseStamped` on `/rpkm/tcp_pose`, `tf2_msgs/TFMessage` on `/tf` and
//! `sensor_msgs/JointState` on `/joint_states`, and every one must carry, bit for bit in SI,
//! the TcpEstimate or ActuatorState with the same stamp that this test receives over
//! iceoryx2; the quaternion must encode ψ (yaw = ψ).
//!
//! The chain: CSV rows on ingest's stdin (poses of a machine with γ2 = 0.02 rad, so that ψ is
//! not 0; ingest's reachability check is the nominal machine's, which a larger γ2 fails) →
//! ingest (`view_every` 1) → tcp_estimator (`view_every` 3: the pose views must
//! be every third estimate). Rows keep coming until the peer has its samples (DDS matching
//! takes a while; a bounded wait, no sleep-then-assert).
//!
//! Needs the venv (`python3 -m venv .venv && .venv/bin/pip install -r
//! tests/python/requirements.txt`); without it SKIPPED, under RPKM_REQUIRE_PYTHON=1 a failure.

use crate::node_support;

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use node_support::{python, rpkm, unique, Proc};
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE};
use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::{ActuatorState, TcpEstimate, Time};
use rpkm_transport::{topic, Transport, TransportConfig};
use serde_json::Value;

const DOMAIN: &str = "74";
const GAMMA2_RAD: f64 = 0.02;
const POSE_EVERY: u64 = 3;
/// Samples of each view the peer must receive.
const COUNT: usize = 20;

/// CSV row `k` of the campaign stream: a pose of the γ2 machine on a slow figure, drive
/// forces from the core's elastic model with q3 pushed 0.05 mm (so that efforts differ).
fn row(p: &Params, k: usize) -> String {
    let s = k as f64;
    let (x, y) = (20.0 * (s / 20.0).sin(), 1650.0 + 30.0 * (s / 30.0).cos());
    let mut q = igm(p, Model::M29, x, y).expect("igm").q();
    q[2] += 0.05;
    let f = fegm(p, &Stiffness::default(), q, ALL_ACTIVE)
        .expect("fegm")
        .drive_force;
    let t = 100.0 + s * 1e-3;
    format!(
        "{t},A,none,0,{},{},{},{},{},{},{},{},,,,,\n",
        q[0], q[1], q[2], q[3], f[0], f[1], f[2], f[3]
    )
}

fn bits(v: f64) -> Value {
    Value::from(v.to_bits())
}

fn stamp_of(v: &Value) -> (i64, u64) {
    let s = &v["header"]["stamp"];
    (s[0].as_i64().expect("sec"), s[1].as_u64().expect("nanosec"))
}

fn key(t: Time) -> (i64, u64) {
    (i64::from(t.sec), u64::from(t.nanosec))
}

/// The yaw of the quaternion (x, y, z, w) of a view, from its bit patterns.
fn yaw(q: &Value) -> f64 {
    let c: Vec<f64> = (0..4)
        .map(|i| f64::from_bits(q[i].as_u64().expect("bits")))
        .collect();
    let norm = c.iter().map(|v| v * v).sum::<f64>();
    assert!((norm - 1.0).abs() < 1e-15, "not a unit quaternion: {c:?}");
    (2.0 * (c[3] * c[2] + c[0] * c[1])).atan2(1.0 - 2.0 * (c[1] * c[1] + c[2] * c[2]))
}

fn check_pose(v: &Value, e: &TcpEstimate) {
    assert_eq!(v["header"]["frame_id"], "machine");
    assert_eq!(
        v["position"],
        serde_json::json!([bits(e.x), bits(e.y), bits(0.0)])
    );
    let psi = yaw(&v["orientation"]);
    assert!((psi - e.psi).abs() < 1e-15, "yaw {psi} vs ψ {}", e.psi);
}

fn check_tf(v: &Value, e: &TcpEstimate) {
    let ts = v.as_array().expect("transforms");
    assert_eq!(ts.len(), 1, "{v}");
    let t = &ts[0];
    assert_eq!(t["header"]["frame_id"], "machine");
    assert_eq!(t["child_frame_id"], "platform");
    assert_eq!(
        t["translation"],
        serde_json::json!([bits(e.x), bits(e.y), bits(0.0)])
    );
    let psi = yaw(&t["rotation"]);
    assert!((psi - e.psi).abs() < 1e-15, "yaw {psi} vs ψ {}", e.psi);
}

fn check_joint(v: &Value, s: &ActuatorState) {
    assert_eq!(v["name"], serde_json::json!(["q1", "q2", "q3", "q4"]));
    assert_eq!(v["position"], Value::from(s.position.map(bits).to_vec()));
    assert_eq!(v["effort"], Value::from(s.force.map(bits).to_vec()));
    assert_eq!(v["velocity"], serde_json::json!([]));
}

/// What the test has received, keyed by stamp.
#[derive(Default)]
struct Seen {
    states: HashMap<(i64, u64), ActuatorState>,
    estimates: HashMap<(i64, u64), TcpEstimate>,
    poses: Vec<Value>,
    tfs: Vec<Value>,
    joints: Vec<Value>,
    done: bool,
}

fn spawn_peer(py: &Path) -> (Proc, mpsc::Receiver<String>) {
    let mut child = Command::new(py)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/ros2_views_peer.py"))
        .args(["--domain", DOMAIN, "--timeout", "90"])
        .args(["--count", &COUNT.to_string()])
        .stdout(Stdio::piped())
        .spawn()
        .expect("start ros2_views_peer.py");
    let out = child.stdout.take().expect("stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (Proc(child), rx)
}

fn spawn_node(args: &[&str], prefix: &str, stdin: Stdio) -> Proc {
    Proc(
        Command::new(rpkm())
            .arg("node")
            .args(args)
            .env("RPKM_IPC_PREFIX", prefix)
            .env("ROS_DOMAIN_ID", DOMAIN)
            .stdin(stdin)
            .spawn()
            .expect("start node"),
    )
}

fn take_peer_line(line: &str, seen: &mut Seen) {
    if line == "DONE" {
        seen.done = true;
        return;
    }
    assert!(!line.starts_with("TIMEOUT"), "peer: {line}");
    let Ok(v) = serde_json::from_str::<Value>(line) else {
        return; // READY
    };
    if let Some(p) = v.get("pose") {
        seen.poses.push(p.clone());
    } else if let Some(t) = v.get("tf") {
        seen.tfs.push(t.clone());
    } else if let Some(j) = v.get("joint") {
        seen.joints.push(j.clone());
    }
}

/// Feeds rows to ingest until the peer is done, draining everything meanwhile.
fn run_until_done(stdin: &mut ChildStdin, peer: &mpsc::Receiver<String>, t: &Transport) -> Seen {
    let mut p = Params::nominal();
    assert!(p.set("gamma2", GAMMA2_RAD));
    let states = t.subscriber(&topic::ACTUATOR_STATE).expect("sub states");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("sub estimates");
    stdin
        .write_all(b"t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi\n")
        .expect("header");
    let mut seen = Seen::default();
    let deadline = Instant::now() + Duration::from_secs(90);
    let mut k = 0;
    // After the peer is done, a bounded while longer for the iceoryx2 side to catch up.
    let mut until: Option<Instant> = None;
    while Instant::now() < until.unwrap_or(deadline) {
        if until.is_none() {
            k += 1;
            stdin.write_all(row(&p, k).as_bytes()).expect("row");
        }
        while let Some(s) = states.try_recv().expect("states") {
            seen.states.insert(key(s.stamp), s);
        }
        while let Some(e) = estimates.try_recv().expect("estimates") {
            seen.estimates.insert(key(e.stamp), e);
        }
        while let Ok(line) = peer.try_recv() {
            take_peer_line(&line, &mut seen);
        }
        if seen.done && until.is_none() {
            until = Some(Instant::now() + Duration::from_secs(5));
        }
        if until.is_some() && all_matched(&seen) {
            break;
        }
        std::thread::sleep(Duration::from_millis(4));
    }
    assert!(
        seen.done,
        "the peer did not get {COUNT} of each view within 90 s ({} rows): {} poses, {} tfs, \
         {} joint states",
        k,
        seen.poses.len(),
        seen.tfs.len(),
        seen.joints.len()
    );
    seen
}

fn all_matched(seen: &Seen) -> bool {
    let est = |v: &Value| seen.estimates.contains_key(&stamp_of(v));
    seen.poses.iter().all(est)
        && seen.tfs.iter().all(|v| est(&v[0]))
        && seen
            .joints
            .iter()
            .all(|v| seen.states.contains_key(&stamp_of(v)))
}

#[test]
fn a_cyclone_peer_receives_pose_tf_and_joint_states_mirroring_the_rpkm_messages() {
    let Some(py) = python() else { return };
    let prefix = unique("r2v");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let (_peer, rx) = spawn_peer(&py);
    let gamma2 = format!("geometry.gamma2={GAMMA2_RAD}");
    let every = format!("view_every={POSE_EVERY}");
    let _estimator = spawn_node(
        &[
            "tcp_estimator",
            "--backend",
            "both",
            "--input-backend",
            "ipc",
            "--param",
            &gamma2,
            "--param",
            &every,
            "--param",
            "follow_parameters=false",
        ],
        &prefix,
        Stdio::null(),
    );
    let mut ingest = spawn_node(
        &[
            "ingest",
            "--source",
            "stdin",
            "--backend",
            "both",
            "--param",
            "view_every=1",
            "--param",
            "start_delay_s=0",
        ],
        &prefix,
        Stdio::piped(),
    );
    let mut stdin = ingest.0.stdin.take().expect("ingest stdin");
    let seen = run_until_done(&mut stdin, &rx, &t);

    let mut pose_seqs = Vec::new();
    for v in &seen.poses {
        let e = seen
            .estimates
            .get(&stamp_of(v))
            .unwrap_or_else(|| panic!("no TcpEstimate with the stamp of pose {v}"));
        check_pose(v, e);
        assert!((e.psi - GAMMA2_RAD).abs() < 0.002, "ψ {} near γ2", e.psi);
        pose_seqs.push(e.seq);
    }
    for v in &seen.tfs {
        let e = seen
            .estimates
            .get(&stamp_of(&v[0]))
            .unwrap_or_else(|| panic!("no TcpEstimate with the stamp of tf {v}"));
        check_tf(v, e);
    }
    for v in &seen.joints {
        let s = seen
            .states
            .get(&stamp_of(v))
            .unwrap_or_else(|| panic!("no ActuatorState with the stamp of joint state {v}"));
        check_joint(v, s);
    }
    // Every third estimate the estimator made: the view counts the estimates it made, so its
    // phase follows the first drive state that reached the estimator (a state published
    // before the DDS endpoints matched is lost to it, and shifts the phase, not the spacing).
    assert!(
        pose_seqs.windows(2).all(|w| w[1] - w[0] == POSE_EVERY),
        "pose views at seq {pose_seqs:?}"
    );
    eprintln!(
        "checked {} poses (ψ {:.6} rad at seq {:?}), {} transforms, {} joint states",
        seen.poses.len(),
        seen.estimates.values().next().map_or(f64::NAN, |e| e.psi),
        pose_seqs.first(),
        seen.tfs.len(),
        seen.joints.len()
    );
    drop(stdin);
}
