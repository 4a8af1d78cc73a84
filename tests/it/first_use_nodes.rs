//! Issue 41, items 8 and 9: the node set as a first user met it, over real processes and
//! iceoryx2, read back through `rpkm monitor --once --json`:
//! - `bags/preload_fault` replayed into nodes on nominal parameters was ERROR from the first
//!   status; the bag carries the machine's Parameters now, and the preload monitor and the
//!   monitor use them: the first statuses are OK and the fault develops;
//! - a monitor started after the calibration said "Parameters: none received yet"; it shows
//!   the calibrator's Parameters (transient-local) now;
//! - `record:=true` gave "NOT HEARD: recorder": the launch's executables are no nodes;
//! - an ERROR of the nominal parameters stayed after Parameters replaced them;
//! - "drive states at 1 Hz" beside "estimates at 403 Hz": rates of streams that arrive alike.

use crate::bag_support;
use crate::node_support;

use std::io::Read;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use node_support::{twin_stream, unique, Launch, TempDir};
use rpkm_msgs::PreloadStatus;
use rpkm_transport::{topic, Subscriber, Transport, TransportConfig};
use serde_json::Value;

/// `rpkm monitor --once --json --window S` on the set with `prefix`, started now.
fn monitor(prefix: &str, window_s: f64) -> Child {
    Command::new(node_support::rpkm())
        .args(["monitor", "--once", "--json", "--window"])
        .arg(window_s.to_string())
        .args(["--ipc-prefix", prefix])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start rpkm monitor")
}

/// The monitor's snapshot, once it has printed it.
fn snapshot(mut m: Child) -> Value {
    let mut out = String::new();
    m.stdout
        .take()
        .expect("piped")
        .read_to_string(&mut out)
        .expect("read the snapshot");
    let status = m.wait().expect("monitor ends");
    let mut err = String::new();
    if let Some(mut e) = m.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    assert!(status.success(), "rpkm monitor: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"))
}

/// Waits until every node of `names` reports on /diagnostics (they are subscribed then).
fn wait_reporting(sub: &Subscriber<rpkm_msgs::DiagnosticArray>, names: &[&str]) {
    let mut heard = std::collections::BTreeSet::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while !names.iter().all(|n| heard.contains(&format!("rpkm/{n}"))) {
        assert!(Instant::now() < deadline, "not reporting: {heard:?}");
        while let Some(d) = sub.try_recv().expect("recv") {
            heard.extend(d.status.into_iter().map(|s| s.name));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A launch file in `dir` with `nodes` (their parameters from the folder's params.yaml) and
/// the recorder as `record:=true` starts it.
fn launch_file(dir: &TempDir, nodes: &str) -> std::path::PathBuf {
    let file = dir.path("first_use.launch.yaml");
    let text = format!(
        "launch:\n{nodes}  - executable: {{cmd: rpkm record --out-dir {}, name: recorder}}\n",
        dir.0.display()
    );
    std::fs::write(&file, text).expect("launch file");
    file
}

fn node(exec: &str, args: &str) -> String {
    format!("  - node: {{pkg: rpkm, exec: {exec}, param: [{{from: params.yaml}}]{args}}}\n")
}

/// The recorder is in the launch's list as an executable, running, and nobody waits for it.
fn assert_recorder_is_no_node(snap: &Value) {
    let launch = snap["launch"].as_array().expect("the launch reports");
    let recorder = launch
        .iter()
        .find(|e| e["name"] == "recorder")
        .expect("recorder listed");
    assert_eq!(recorder["executable"], true, "{recorder}");
    assert_eq!(recorder["state"], "running", "{recorder}");
    assert_eq!(snap["not_heard"], serde_json::json!([]), "{snap}");
}

/// Item 8: the bag's Parameters reach the preload monitor before the stream: the first
/// status is OK (nominal parameters gave ERROR at once), then WARN and ERROR follow the fault;
/// the monitor shows the bag's Parameters, the recorder as an executable, and the drive
/// states and estimates of the stream at alike rates.
#[test]
fn a_replayed_bags_parameters_are_used_and_the_fault_develops() {
    let dir = TempDir::new("fu-replay");
    std::fs::write(
        dir.path("params.yaml"),
        "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n\
         preload_monitor:\n  ros__parameters:\n    status_every: 1\n",
    )
    .expect("params.yaml");
    let file = launch_file(
        &dir,
        &(node("tcp_estimator", "") + &node("preload_monitor", "")),
    );
    let prefix = unique("fureplay");
    let t = Transport::new(&TransportConfig::new(unique("fuobs")).ipc_prefix(&prefix))
        .expect("transport");
    let statuses = t.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let diagnostics = t.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let mut launched = Launch::start(&file, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    wait_reporting(&diagnostics, &["tcp_estimator", "preload_monitor"]);
    // the stream (at half speed) runs from 2 s to 6 s after the replay starts: the snapshot
    // falls inside it
    let watcher = monitor(&prefix, 5.0);
    let mut replay = bag_support::Watched::spawn(
        bag_support::rpkm()
            .arg("replay")
            .arg(bag_support::reference_bag("preload_fault"))
            .args(["--rate", "0.5", "--ipc-prefix", &prefix]),
    );
    let mut levels: Vec<u8> = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(90);
    while levels.len() < 2000 && Instant::now() < deadline {
        while let Some(s) = statuses.try_recv().expect("recv") {
            levels.push(s.level);
        }
        // reliable: a subscriber that stops taking holds its publishers up
        while diagnostics.try_recv().expect("recv").is_some() {}
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(replay.wait(Duration::from_secs(60)).success(), "replay");
    let snap = snapshot(watcher);
    launched.stop();
    assert_eq!(levels.len(), 2000, "one status per sample");
    assert_eq!(
        levels[0],
        PreloadStatus::OK,
        "the first status, with the bag's geometry"
    );
    let first = |l: u8| levels.iter().position(|&v| v == l).expect("reached");
    assert!(first(PreloadStatus::WARN) < first(PreloadStatus::ERROR));
    assert_eq!(levels.last(), Some(&PreloadStatus::ERROR));
    let p = &snap["parameters"];
    assert_eq!(
        (p["model"].as_u64(), p["identified"].as_u64()),
        (Some(29), Some(0)),
        "{p}"
    );
    assert_recorder_is_no_node(&snap);
    let states = snap["actuator_state"]["rate_hz"].as_f64().expect("rate");
    let estimates = snap["tcp_estimate"]["rate_hz"].as_f64().expect("rate");
    eprintln!(
        "first WARN at sample {}, first ERROR at {}; drive states {states:.0} Hz, estimates \
         {estimates:.0} Hz",
        first(PreloadStatus::WARN),
        first(PreloadStatus::ERROR)
    );
    assert!(
        states > 100.0 && (states - estimates).abs() < 0.25 * states,
        "drive states at {states} Hz, estimates at {estimates} Hz"
    );
}

/// Item 9: a monitor started after the calibration shows the calibrator's Parameters (and
/// knows the recorder for an executable).
#[test]
fn a_monitor_started_late_shows_the_calibration() {
    let dir = TempDir::new("fu-late");
    std::fs::write(
        dir.path("params.yaml"),
        "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n\
         ingest:\n  ros__parameters:\n    rate_hz: 2000.0\n    start_delay_s: 1.0\n",
    )
    .expect("params.yaml");
    let campaign = bag_support::repo_root().join("bags/demo/campaign.csv");
    let nodes = node(
        "ingest",
        &format!(", args: --source {}", campaign.display()),
    ) + &node("calibrator", "");
    let file = launch_file(&dir, &nodes);
    let prefix = unique("fulate");
    let launched = Launch::start(&file, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    launched.wait_for("calibration 1:", Duration::from_secs(120));
    // a window long enough for a loaded host to join and hear the late Parameters
    let snap = snapshot(monitor(&prefix, 3.0));
    drop(launched);
    let p = &snap["parameters"];
    assert_eq!(p["model"], 29, "{snap}");
    assert!(p["measurement_count"].as_u64() > Some(100), "{p}");
    assert_recorder_is_no_node(&snap);
}

/// Item 9: on nominal parameters the twin's stream is ERROR; once Parameters with the twin's
/// geometry replace them, the statuses are OK and the monitor's first ERROR is gone with the
/// model that raised it.
#[test]
fn an_alarm_goes_with_the_model_that_raised_it() {
    let dir = TempDir::new("fu-alarm");
    let stream = twin_stream(800, 200.0, |_| 0.0);
    let csv = dir.path("stream.csv");
    std::fs::write(&csv, stream.campaign.to_csv()).expect("write stream");
    std::fs::write(
        dir.path("params.yaml"),
        "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n\
         ingest:\n  ros__parameters:\n    rate_hz: 200.0\n    start_delay_s: 1.0\n\
         preload_monitor:\n  ros__parameters:\n    warn_percent: 2.0\n    error_percent: 4.0\n    \
         status_every: 1\n",
    )
    .expect("params.yaml");
    let nodes = node("ingest", &format!(", args: --source {}", csv.display()))
        + &node("preload_monitor", "");
    let file = launch_file(&dir, &nodes);
    let prefix = unique("fualarm");
    let t = Transport::new(&TransportConfig::new(unique("fuobs")).ipc_prefix(&prefix))
        .expect("transport");
    let statuses = t.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let parameters = t.publisher(&topic::PARAMETERS).expect("pub");
    // the monitor from before the stream: it sees the nominal parameters' ERROR
    let watcher = monitor(&prefix, 8.0);
    let mut launched = Launch::start(&file, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let levels = replace_after_errors(&statuses, &parameters, stream.twin.true_params());
    let snap = snapshot(watcher);
    launched.stop();
    assert_eq!(levels.last(), Some(&PreloadStatus::OK), "{levels:?}");
    let pre = &snap["preload"];
    let replaced = snap["model_replaced_s"]
        .as_f64()
        .expect("the model was replaced");
    assert!(
        pre["first_error_s"].as_f64().is_none_or(|t| t > replaced),
        "the nominal parameters' ERROR stayed: {pre}"
    );
    assert_eq!(pre["level"], "OK", "{pre}");
}

/// Collects the statuses; after 20 ERROR statuses publishes the twin's geometry as
/// Parameters; returns the levels once the stream is over.
fn replace_after_errors(
    statuses: &Subscriber<PreloadStatus>,
    parameters: &rpkm_transport::Publisher<rpkm_msgs::Parameters>,
    p: &rpkm_core::params::Params,
) -> Vec<u8> {
    let mut levels = Vec::new();
    let mut sent = false;
    let deadline = Instant::now() + Duration::from_secs(60);
    while levels.len() < 800 && Instant::now() < deadline {
        while let Some(s) = statuses.try_recv().expect("recv") {
            levels.push(s.level);
        }
        // the levels are held, debounced: past ERROR once the last is ERROR for a while
        let errors = levels.len()
            - levels
                .iter()
                .rposition(|&l| l != PreloadStatus::ERROR)
                .map_or(0, |k| k + 1);
        if !sent && errors >= 20 {
            let sigmas = [0.0; rpkm_core::params::N_PARAMS];
            let msg = rpkm_nodes::node::geometry::parameters_msg(
                p,
                rpkm_core::params::Model::M29,
                &sigmas,
            );
            parameters.publish(&msg).expect("publish Parameters");
            sent = true;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(sent, "nominal parameters gave no ERROR: {levels:?}");
    levels
}

/// Item 8: the shipped launch file takes the user's calibration and written effects
/// (`geometry_file:=`, `effects_file:=`) to the three nodes that evaluate the model, which
/// read them (`--check` loads every node's parameters as the node does: a missing file is
/// exit 2 naming it); left empty, nothing is passed and params.yaml's keys stand.
#[test]
fn the_launch_file_takes_the_users_geometry_and_effects() {
    let dir = TempDir::new("fu-launch");
    let geometry = dir.path("calibrated.json");
    node_support::write_truth_json(&rpkm_core::params::Params::nominal(), &geometry);
    let effects = dir.path("mine.yaml");
    std::fs::write(
        &effects,
        "effects:\n  - name: lost_motion_q4\n    summary: carrier 4 lags\n    \
         params: {b: {unit: mm, prior: 0.02}}\n    dq4: \"-b * dir_q4\"\n",
    )
    .expect("effects file");
    let file = bag_support::repo_root().join("launch_scripts/rpkm.launch.yaml");
    let check = |args: &[String]| {
        let out = Command::new(node_support::rpkm())
            .arg("launch")
            .arg(&file)
            .args(args)
            .arg("--check")
            .output()
            .expect("rpkm launch --check");
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        (out.status.code(), text)
    };
    let given = [
        format!("geometry_file:={}", geometry.display()),
        format!("effects_file:={}", effects.display()),
    ];
    let (code, text) = check(&given);
    assert_eq!(code, Some(0), "{text}");
    for exec in ["tcp_estimator", "calibrator", "preload_monitor"] {
        let line = text
            .lines()
            .find(|l| l.contains(&format!(": {exec}: rpkm-node {exec}")))
            .unwrap_or_else(|| panic!("no {exec}: {text}"));
        assert!(
            line.contains(&format!("--param=geometry_file={}", geometry.display()))
                && line.contains(&format!("--param=effects_file={}", effects.display())),
            "{line}"
        );
    }
    let missing = dir.path("nope.json");
    let (code, text) = check(&[format!("geometry_file:={}", missing.display())]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains(&missing.display().to_string()), "{text}");
    let (code, text) = check(&[]);
    assert_eq!(code, Some(0), "{text}");
    assert!(!text.contains("--param=geometry_file"), "{text}");
}
