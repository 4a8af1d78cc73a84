//! `preload_monitor` as a ROS 2 citizen, checked by an independent DDS peer: Eclipse Cyclone
//! DDS (tests/python/ros2_params_peer.py) calls the node's parameter services as `ros2 param`
//! on rmw_cyclonedds does (request id header in the payload), and reads `/parameter_events`
//! and `/rosout`.
//!
//! The test feeds the monitor one drive state over iceoryx2, again and again: the nominal
//! machine at (0, 1700) mm with the drive forces of q3 pushed 0.12 mm (the core's elastic
//! model gives the deviation, between the default WARN 20 % and ERROR 50 %). The monitor
//! holds WARN; then the peer sets `warn_percent` above the deviation and the monitor's
//! PreloadStatus must go to OK while the same state keeps coming. Refused sets (out of range,
//! read-only, error below warn) must say why and leave the value as it was.
//!
//! Needs the venv (`python3 -m venv .venv && .venv/bin/pip install -r
//! tests/python/requirements.txt`); without it SKIPPED, under RPKM_REQUIRE_PYTHON=1 a failure.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use crate::node_support;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use node_support::{python, rpkm, unique, Proc, TempDir};
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE, NOMINAL_DRIVE_FORCE_N};
use rpkm_core::geometry::igm;
use rpkm_core::params::{Model, Params};
use rpkm_msgs::{ActuatorState, PreloadStatus, Time};
use rpkm_transport::{topic, Transport, TransportConfig};
use serde_json::Value;

const DOMAIN: &str = "71";
/// The first-calls test's domain.
const FIRST_CALLS_DOMAIN: &str = "72";

/// The state and its largest |measured − predicted| current, %, from the core.
fn state_with_deviation() -> (ActuatorState, f64) {
    let p = Params::nominal();
    let q = igm(&p, Model::M29, 0.0, 1700.0).expect("igm").q();
    let predicted = fegm(&p, &Stiffness::default(), q, ALL_ACTIVE).expect("fegm");
    let mut pushed = q;
    pushed[2] += 0.12;
    let measured = fegm(&p, &Stiffness::default(), pushed, ALL_ACTIVE).expect("fegm");
    let worst = (0..4)
        .map(|i| (measured.drive_force[i] - predicted.drive_force[i]).abs())
        .fold(0.0, f64::max)
        / NOMINAL_DRIVE_FORCE_N
        * 100.0;
    let state = ActuatorState {
        position: q.map(|v| v / 1e3),
        force: measured.drive_force,
        ..Default::default()
    };
    (state, worst)
}

/// Publishes `state` (seq counting up) every 2 ms until a PreloadStatus with `level` arrives.
fn drive_until_level(
    t: &Transport,
    state: &mut ActuatorState,
    statuses: &rpkm_transport::Subscriber<PreloadStatus>,
    level: u8,
    what: &str,
) -> PreloadStatus {
    let publisher = t.publisher(&topic::ACTUATOR_STATE).expect("pub");
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        state.seq += 1;
        state.stamp = Time {
            sec: 100,
            nanosec: state.seq as u32,
        };
        publisher.publish(state).expect("publish");
        while let Some(s) = statuses.try_recv().expect("recv") {
            if s.level == level {
                return s;
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("{what}: no PreloadStatus with level {level} within 30 s");
}

/// Runs the peer on `script`; its JSON lines come back through the channel.
fn peer(py: &Path, dir: &TempDir, node: &str, script: &Value) -> (Proc, mpsc::Receiver<Value>) {
    peer_on(py, dir, (DOMAIN, node), script)
}

/// [`peer`] on domain `domain`.
fn peer_on(
    py: &Path,
    dir: &TempDir,
    (domain, node): (&str, &str),
    script: &Value,
) -> (Proc, mpsc::Receiver<Value>) {
    let file = dir.path("script.json");
    std::fs::write(&file, script.to_string()).expect("script");
    let mut child = Command::new(py)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/ros2_params_peer.py"))
        .args(["--domain", domain, "--timeout", "60", "--node", node])
        .arg(&file)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start ros2_params_peer.py");
    let out = child.stdout.take().expect("stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            let v: Value = serde_json::from_str(&line).unwrap_or(Value::String(line));
            if tx.send(v).is_err() {
                break;
            }
        }
    });
    (Proc(child), rx)
}

/// The peer's next line. The monitor's PreloadStatus queue is drained meanwhile: the topic is
/// reliable, and a full queue of a live subscriber holds the monitor's loop (and with it
/// the parameter changes it applies) until the subscriber takes.
fn next(
    rx: &mpsc::Receiver<Value>,
    statuses: &rpkm_transport::Subscriber<PreloadStatus>,
    what: &str,
) -> Value {
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        while statuses.try_recv().expect("recv").is_some() {}
        match rx.recv_timeout(Duration::from_millis(20)) {
            Ok(v) => {
                assert!(v.get("timeout").is_none(), "{what}: {v}");
                return v;
            }
            Err(_) if Instant::now() < deadline => {}
            Err(e) => panic!("the peer gave no answer for {what} within 60 s: {e}"),
        }
    }
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn a_cyclone_peer_sets_a_threshold_and_the_monitor_level_follows_live() {
    let Some(py) = python() else { return };
    let (mut state, deviation) = state_with_deviation();
    assert!(
        (20.0..50.0).contains(&deviation),
        "the state must be WARN at the defaults: {deviation} %"
    );
    let dir = TempDir::new("ros2params");
    let prefix = unique("r2p");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let statuses = t.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let _node = Proc(
        Command::new(rpkm())
            .args(["node", "preload_monitor", "--backend", "both"])
            .args(["--input-backend", "ipc", "--param", "debounce_samples=1"])
            .args(["--param", "follow_parameters=false"])
            .env("RPKM_IPC_PREFIX", &prefix)
            .env("ROS_DOMAIN_ID", DOMAIN)
            .spawn()
            .expect("start preload_monitor"),
    );
    let warn = drive_until_level(&t, &mut state, &statuses, PreloadStatus::WARN, "defaults");
    let worst = warn.deviation.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    assert!((worst - deviation).abs() < 1e-6, "{worst} vs {deviation}");

    let above = (deviation + 5.0).round();
    let script = serde_json::json!([
        {"get": ["warn_percent", "error_percent", "backend"]},
        {"describe": ["warn_percent", "debounce_samples", "backend"]},
        {"set": {"warn_percent": -5.0}},
        {"set": {"backend": "dds"}},
        {"set": {"error_percent": 10.0}},
        {"set": {"debounce_samples": 0}},
        {"get": ["warn_percent", "error_percent", "debounce_samples"]},
        {"set": {"warn_percent": above}},
        {"await_event": "warn_percent"},
        {"await_rosout": "parameters set: warn_percent"},
    ]);
    let (_peer, rx) = peer(&py, &dir, "/rpkm/preload_monitor", &script);
    let get = next(&rx, &statuses, "get");
    assert_eq!(get["get"]["warn_percent"], serde_json::json!([3, 20.0]));
    assert_eq!(get["get"]["error_percent"], serde_json::json!([3, 50.0]));
    assert_eq!(get["get"]["backend"], serde_json::json!([4, "both"]));
    let describe = next(&rx, &statuses, "describe");
    let d = &describe["describe"];
    assert_eq!(d["warn_percent"]["read_only"], false);
    assert_eq!(d["backend"]["read_only"], true);
    assert_eq!(
        d["debounce_samples"]["integer_range"],
        serde_json::json!([[1, 1_000_000]])
    );
    let refused = |v: &Value, key: &str, why: &str| {
        let r = &v["set"][key];
        assert_eq!(r[0], false, "{key} must be refused: {v}");
        let reason = r[1].as_str().unwrap_or_default();
        assert!(
            reason.contains(why),
            "{key}: reason {reason:?} lacks {why:?}"
        );
    };
    refused(
        &next(&rx, &statuses, "set -5"),
        "warn_percent",
        "a number > 0",
    );
    refused(&next(&rx, &statuses, "set backend"), "backend", "read-only");
    refused(
        &next(&rx, &statuses, "set error 10"),
        "error_percent",
        "below warn_percent",
    );
    refused(
        &next(&rx, &statuses, "set debounce 0"),
        "debounce_samples",
        "out of range",
    );
    let unchanged = next(&rx, &statuses, "get after refusals");
    assert_eq!(
        unchanged["get"],
        serde_json::json!({"warn_percent": [3, 20.0], "error_percent": [3, 50.0],
            "debounce_samples": [2, 1]})
    );
    let set = next(&rx, &statuses, "set warn_percent");
    assert_eq!(set["set"]["warn_percent"], serde_json::json!([true, ""]));
    let event = next(&rx, &statuses, "parameter event");
    assert_eq!(event["event"]["node"], "/rpkm/preload_monitor");
    assert_eq!(event["event"]["value"], serde_json::json!([3, above]));
    let rosout = next(&rx, &statuses, "rosout");
    assert_eq!(rosout["rosout"]["name"], "rpkm.preload_monitor");
    assert_eq!(rosout["rosout"]["level"], 20, "INFO");

    // The same state, now below WARN: the held level goes to OK.
    let ok = drive_until_level(
        &t,
        &mut state,
        &statuses,
        PreloadStatus::OK,
        "after the set",
    );
    let worst = ok.deviation.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    assert!(
        (worst - deviation).abs() < 1e-6 && worst < above,
        "{worst} vs {deviation}"
    );
}

/// The peer's next line, within 60 s.
fn next_line(rx: &mpsc::Receiver<Value>, what: &str) -> Value {
    let v = rx
        .recv_timeout(Duration::from_secs(60))
        .unwrap_or_else(|_| panic!("the peer gave no answer for {what} within 60 s"));
    assert!(v.get("timeout").is_none(), "{what}: {v}");
    v
}

/// A tcp_estimator on DDS (`view_every` 7) in domain `domain`, its iceoryx2 under `prefix`.
fn estimator(prefix: &str, domain: &str) -> Proc {
    Proc(
        Command::new(rpkm())
            .args(["node", "tcp_estimator", "--backend", "both"])
            .args(["--input-backend", "ipc", "--param", "view_every=7"])
            .args(["--param", "follow_parameters=false"])
            .env("RPKM_IPC_PREFIX", prefix)
            .env("ROS_DOMAIN_ID", domain)
            .spawn()
            .expect("start tcp_estimator"),
    )
}

/// tcp_estimator on the same services: `view_every` (the decimation of its standard views)
/// is set live, `views` and `rt_priority` need a restart and are refused.
#[test]
fn a_cyclone_peer_reads_and_sets_the_estimators_parameters() {
    let Some(py) = python() else { return };
    let dir = TempDir::new("ros2params_est");
    let _node = estimator(&unique("r2pe"), DOMAIN);
    let script = serde_json::json!([
        {"get": ["view_every", "views", "model", "rt_priority"]},
        {"describe": ["view_every", "views"]},
        {"set": {"view_every": 0}},
        {"set": {"views": false}},
        {"set": {"view_every": 2}},
        {"await_event": "view_every"},
        {"await_rosout": "parameters set: view_every"},
    ]);
    let (_peer, rx) = peer(&py, &dir, "/rpkm/tcp_estimator", &script);
    let get = next_line(&rx, "get");
    assert_eq!(
        get["get"],
        serde_json::json!({"view_every": [2, 7], "views": [1, true], "model": [2, 29],
            "rt_priority": [2, 0]})
    );
    let d = &next_line(&rx, "describe")["describe"];
    assert_eq!(d["view_every"]["read_only"], false);
    assert_eq!(
        d["view_every"]["integer_range"],
        serde_json::json!([[1, 1_000_000]])
    );
    assert_eq!(d["views"]["read_only"], true);
    let zero = next_line(&rx, "set 0");
    assert_eq!(zero["set"]["view_every"][0], false, "{zero}");
    let views = next_line(&rx, "set views");
    assert_eq!(views["set"]["views"][0], false, "{views}");
    let reason = views["set"]["views"][1].as_str().unwrap_or_default();
    assert!(reason.contains("read-only"), "{reason}");
    let set = next_line(&rx, "set 2");
    assert_eq!(set["set"]["view_every"], serde_json::json!([true, ""]));
    let event = next_line(&rx, "event");
    assert_eq!(event["event"]["node"], "/rpkm/tcp_estimator");
    assert_eq!(event["event"]["value"], serde_json::json!([2, 2]));
    let rosout = next_line(&rx, "rosout");
    assert_eq!(rosout["rosout"]["name"], "rpkm.tcp_estimator");
}

/// Issue 51: a one-shot client's first call gets its reply. 100 fresh clients (each a new
/// request writer and reply reader, as each `ros2 param get` is) call get_parameters once,
/// as soon as both are matched, with no resend: the reply must wait for the client's reply
/// reader, whose discovery by the server races the request (before, about 1 in 10 was lost).
#[test]
fn a_hundred_fresh_clients_each_get_the_reply_to_their_one_call() {
    let Some(py) = python() else { return };
    let dir = TempDir::new("ros2params_first");
    // a domain of its own: the estimator of the test above has the same name
    let _node = estimator(&unique("r2pf"), FIRST_CALLS_DOMAIN);
    let script = serde_json::json!([{"first_calls": 100, "get": ["view_every"]}]);
    let (_peer, rx) = peer_on(
        &py,
        &dir,
        (FIRST_CALLS_DOMAIN, "/rpkm/tcp_estimator"),
        &script,
    );
    let calls = next_line(&rx, "first calls");
    assert_eq!(
        calls["first_calls"],
        serde_json::json!([100, 100]),
        "{calls}"
    );
}

/// A CSV row of ingest's stdin at `t` s: the nominal machine at (0, 1700) mm, drive forces
/// `f` N (the validator judges their size, not their physics).
fn ingest_row(t: f64, f: [f64; 4]) -> String {
    let q = igm(&Params::nominal(), Model::M29, 0.0, 1700.0)
        .expect("igm")
        .q();
    format!(
        "{t},A,none,0,{},{},{},{},{},{},{},{},,,,,\n",
        q[0], q[1], q[2], q[3], f[0], f[1], f[2], f[3]
    )
}

/// The stamps (s) of the ActuatorStates ingest publishes, until the one at `until` s.
fn states_until(
    states: &rpkm_transport::Subscriber<ActuatorState>,
    until: f64,
    what: &str,
) -> Vec<f64> {
    let mut seen = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        while let Some(s) = states.try_recv().expect("recv") {
            let t = f64::from(s.stamp.sec) + f64::from(s.stamp.nanosec) * 1e-9;
            seen.push(t);
            if (t - until).abs() < 1e-6 {
                return seen;
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    panic!("{what}: no ActuatorState stamped {until} s within 30 s (seen {seen:?})");
}

/// ingest on the same services: `force_max_n` set live judges the next row (a row within the
/// default 43,000 N passes, the same row after the set to 2,500 N is rejected, a smaller one
/// passes); `source` is read-only, a minimum position above the maximum is refused.
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn a_cyclone_peer_sets_an_ingest_limit_and_the_next_row_is_judged_by_it() {
    use std::io::Write;
    let Some(py) = python() else { return };
    let dir = TempDir::new("ros2params_ingest");
    let prefix = unique("r2pi");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let states = t.subscriber(&topic::ACTUATOR_STATE).expect("sub");
    let mut node = Proc(
        Command::new(rpkm())
            .args(["node", "ingest", "--backend", "both", "--source", "stdin"])
            .args(["--param", "start_delay_s=0"])
            .env("RPKM_IPC_PREFIX", &prefix)
            .env("ROS_DOMAIN_ID", DOMAIN)
            .stdin(Stdio::piped())
            .spawn()
            .expect("start ingest"),
    );
    let mut stdin = node.0.stdin.take().expect("ingest stdin");
    let big = [1000.0, -2000.0, 3000.0, -1500.0];
    let small = [1000.0, -2000.0, 2000.0, -1500.0];
    stdin
        .write_all(b"t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi\n")
        .expect("header");
    stdin
        .write_all(ingest_row(100.0, big).as_bytes())
        .expect("row");
    stdin.flush().expect("flush");
    assert_eq!(states_until(&states, 100.0, "before the set"), [100.0]);

    let script = serde_json::json!([
        {"list": true},
        {"get": ["force_max_n", "source", "view_every"]},
        {"describe": ["force_max_n", "rate_hz", "source"]},
        {"set": {"force_max_n": -1.0}},
        {"set": {"source": "dds"}},
        {"set": {"position_min_m": 10.0}},
        {"set": {"force_max_n": 2500.0}},
        {"await_event": "force_max_n"},
        {"await_rosout": "parameters set: force_max_n"},
    ]);
    let (_peer, rx) = peer(&py, &dir, "/rpkm/ingest", &script);
    let list = next_line(&rx, "list");
    let names: Vec<&str> = list["list"]
        .as_array()
        .expect("names")
        .iter()
        .filter_map(Value::as_str)
        .collect();
    for key in rpkm_nodes::node::ingest::PARAMS
        .iter()
        .map(|s| &s.key)
        .chain(&["backend", "input_backend"])
    {
        assert!(names.contains(key), "{key} not listed: {names:?}");
    }
    assert_eq!(
        next_line(&rx, "get")["get"],
        serde_json::json!({"force_max_n": [3, 43000.0], "source": [4, "stdin"],
            "view_every": [2, 100]})
    );
    let d = &next_line(&rx, "describe")["describe"];
    assert_eq!(d["force_max_n"]["read_only"], false);
    assert_eq!(d["rate_hz"]["read_only"], true);
    assert_eq!(
        d["rate_hz"]["float_range"],
        serde_json::json!([[0.001, 1e6]])
    );
    assert_eq!(d["source"]["read_only"], true);
    let refused = |v: &Value, key: &str, why: &str| {
        let r = &v["set"][key];
        assert_eq!(r[0], false, "{key} must be refused: {v}");
        let reason = r[1].as_str().unwrap_or_default();
        assert!(reason.contains(why), "{key}: {reason:?} lacks {why:?}");
    };
    refused(&next_line(&rx, "set -1"), "force_max_n", "> 0");
    refused(&next_line(&rx, "set source"), "source", "read-only");
    refused(
        &next_line(&rx, "set min 10"),
        "position_min_m",
        "below position_max_m",
    );
    let set = next_line(&rx, "set 2500");
    assert_eq!(set["set"]["force_max_n"], serde_json::json!([true, ""]));
    let event = next_line(&rx, "event");
    assert_eq!(event["event"]["node"], "/rpkm/ingest");
    assert_eq!(event["event"]["value"], serde_json::json!([3, 2500.0]));
    // The node logs the line once it has taken the change: the next row is judged by it.
    let rosout = next_line(&rx, "rosout");
    assert_eq!(rosout["rosout"]["name"], "rpkm.ingest");

    stdin
        .write_all(ingest_row(100.001, big).as_bytes())
        .expect("row");
    stdin
        .write_all(ingest_row(100.002, small).as_bytes())
        .expect("row");
    stdin.flush().expect("flush");
    assert_eq!(
        states_until(&states, 100.002, "after the set"),
        [100.002],
        "the 3,000 N row must be rejected at 2,500 N, the 2,000 N row pass"
    );
}

/// The calibrator on the same services: what the next calibration uses is live, the state
/// buffer and the online tracker need a restart, a selection other than map or auto and an
/// outlier threshold beyond 100 σ are refused.
#[test]
fn a_cyclone_peer_reads_and_sets_the_calibrators_parameters() {
    let Some(py) = python() else { return };
    let dir = TempDir::new("ros2params_cal");
    let prefix = unique("r2pc");
    let _node = Proc(
        Command::new(rpkm())
            .args(["node", "calibrator", "--backend", "both"])
            .args(["--input-backend", "ipc", "--param", "calibrate_every=40"])
            .env("RPKM_IPC_PREFIX", &prefix)
            .env("ROS_DOMAIN_ID", DOMAIN)
            .spawn()
            .expect("start calibrator"),
    );
    let script = serde_json::json!([
        {"list": true},
        {"get": ["calibrate_every", "selection", "state_buffer", "model"]},
        {"describe": ["outlier_sigma", "state_buffer", "calibrate_every"]},
        {"set": {"selection": "best"}},
        {"set": {"state_buffer": 10}},
        {"set": {"outlier_sigma": 200.0}},
        {"set": {"selection": "auto"}},
        {"await_event": "selection"},
        {"await_rosout": "parameters set: selection"},
        {"get": ["selection"]},
    ]);
    let (_peer, rx) = peer(&py, &dir, "/rpkm/calibrator", &script);
    let list = next_line(&rx, "list");
    let names = list["list"].as_array().expect("names");
    for key in [
        "calibrate_every",
        "selection",
        "outlier_sigma",
        "state_buffer",
        "online",
    ] {
        assert!(names.iter().any(|n| n == key), "{key} not listed: {list}");
    }
    assert_eq!(
        next_line(&rx, "get")["get"],
        serde_json::json!({"calibrate_every": [2, 40], "selection": [4, "map"],
            "state_buffer": [2, 4096], "model": [2, 29]})
    );
    let d = &next_line(&rx, "describe")["describe"];
    assert_eq!(
        d["outlier_sigma"]["float_range"],
        serde_json::json!([[0.0, 100.0]])
    );
    assert_eq!(d["outlier_sigma"]["read_only"], false);
    assert_eq!(d["state_buffer"]["read_only"], true);
    assert_eq!(
        d["calibrate_every"]["integer_range"],
        serde_json::json!([[0, 1_000_000]])
    );
    let refused = |v: &Value, key: &str, why: &str| {
        let r = &v["set"][key];
        assert_eq!(r[0], false, "{key} must be refused: {v}");
        let reason = r[1].as_str().unwrap_or_default();
        assert!(reason.contains(why), "{key}: {reason:?} lacks {why:?}");
    };
    refused(
        &next_line(&rx, "set best"),
        "selection",
        "expected map or auto",
    );
    refused(&next_line(&rx, "set buffer"), "state_buffer", "read-only");
    refused(
        &next_line(&rx, "set 200 sigma"),
        "outlier_sigma",
        "out of range",
    );
    let set = next_line(&rx, "set auto");
    assert_eq!(set["set"]["selection"], serde_json::json!([true, ""]));
    let event = next_line(&rx, "event");
    assert_eq!(event["event"]["node"], "/rpkm/calibrator");
    assert_eq!(event["event"]["value"], serde_json::json!([4, "auto"]));
    let rosout = next_line(&rx, "rosout");
    assert_eq!(rosout["rosout"]["name"], "rpkm.calibrator");
    assert_eq!(
        next_line(&rx, "get after")["get"],
        serde_json::json!({"selection": [4, "auto"]})
    );
}
