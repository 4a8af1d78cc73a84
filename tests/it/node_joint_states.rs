//! Issue 38: a ros2_control cell needs no bridge. An independent cell on Eclipse Cyclone DDS
//! (tests/python/joint_states_peer.py) plays the demo campaign's drive states and then 100
//! poses of the twin under preload as `sensor_msgs/JointState` on `/joint_states` at 1 kHz
//! (the drives' joints shuffled among another device's, efforts in the joints' sign) and a
//! `sensor_msgs/Temperature` at 10 Hz; the shipped launch file runs the stack with
//! `source:=joint_states` and the parameter block of docs/nodes.md. Checked:
//!
//! - every TcpEstimate and PreloadStatus equals the one of the same campaign through the CSV
//!   source (`joint_states_support::reference`), to 1e-9 m and 1e-6 N, none lost, and so do
//!   the estimates of a second tcp_estimator reading the cell directly (`source:
//!   joint_states`);
//! - the cell switches its controllers before the twin's poses (q2, q3 follow in the demo,
//!   every drive holds after) and says so through the parameter services: the estimates
//!   follow from the next state on (the CSV source has the switch in its rows), the preload
//!   monitor's q2, q3 currents go from 0 (followers) to the drives' forces;
//! - then a JointState without q2's joint, one with arrays of unequal length, one with q3 at
//!   NaN, and the thermometer silent past its timeout: counted and named on /diagnostics,
//!   nothing published from them, and the next state carries the temperature not measured.

use crate::joint_states_support::{
    campaign, cell, estimate_gap, launch_dir, reference, split, status_gap, value, write_script,
    Observed, Observer, Script,
};
use crate::node_support::{python, rpkm, unique, Launch, Proc};

use rpkm_core::elastic::{fegm, Stiffness, FOLLOWERS_23};
use rpkm_core::params::Params;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const DOMAIN: &str = "64";

/// The second estimator, reading the cell directly, in its own namespace.
const DIRECT: &str = "/direct/tcp_estimator";

/// Compares what the stack published from the cell with the CSV source's, pose by pose; the
/// largest gaps (m, N) of the estimates, the direct estimator's and the preload statuses.
fn against_reference(seen: &Observed, n: usize) -> [(f64, f64); 3] {
    let want = reference();
    let mut gaps = [(0.0f64, 0.0f64); 3];
    for seq in 1..=n as u64 {
        let w = &want.estimates[&seq];
        for (i, got) in [&seen.estimates, &seen.extra].iter().enumerate() {
            let e = got
                .get(&seq)
                .unwrap_or_else(|| panic!("no estimate seq {seq}"));
            let (m, f) = estimate_gap(e, w);
            gaps[i] = (gaps[i].0.max(m), gaps[i].1.max(f));
        }
    }
    for (got, w) in seen.statuses.iter().zip(&want.statuses) {
        let (m, f) = status_gap(got, w);
        gaps[2] = (gaps[2].0.max(m), gaps[2].1.max(f));
    }
    gaps
}

/// The follower switch as the estimates and the preload monitor recorded it: the seq of the
/// first state published with every drive holding, and the q2 current (%) before and after.
fn switch_of(seen: &Observed) -> (u64, f64, f64) {
    let first = seen
        .states
        .iter()
        .find(|s| s.follower == [false; 4])
        .expect("a state with every drive holding");
    assert!(
        seen.states
            .iter()
            .skip_while(|s| s.seq < first.seq)
            .all(|s| s.follower == [false; 4]),
        "one switch, from followers 23 to none"
    );
    let at = |stamp| {
        seen.statuses
            .iter()
            .find(|p| p.stamp == stamp)
            .expect("a preload status of the state")
            .measured_current[1]
    };
    let before = seen
        .states
        .iter()
        .rfind(|s| s.seq < first.seq)
        .expect("a state before the switch");
    (first.seq, at(before.stamp), at(first.stamp))
}

/// Ingest's and the direct estimator's /diagnostics after the refused messages and the
/// silent thermometer.
fn refusals_reported(seen: &Observed) {
    let ingest = &seen.diagnostics["rpkm/ingest"];
    eprintln!(
        "ingest /diagnostics: {} {:?}",
        ingest.message, ingest.values
    );
    for (key, want) in [
        ("joint_missing.q2_joint", "1"),
        ("joint_unequal_arrays", "1"),
        ("joint_non_finite.q3_joint", "1"),
        ("rejected_malformed", "2"),
        ("rejected_non_finite", "1"),
        ("thermometers_quiet", "temp_machine"),
        ("followers", "none"),
    ] {
        assert_eq!(value(ingest, key), Some(want), "ingest {key}");
    }
    assert_eq!(ingest.level, rpkm_msgs::DiagnosticStatus::WARN);
    assert!(
        ingest
            .message
            .contains("thermometer temp_machine (/cell/frame_temperature) quiet for"),
        "{}",
        ingest.message
    );
    let direct = &seen.diagnostics["direct/tcp_estimator"];
    assert_eq!(value(direct, "joint_missing.q2_joint"), Some("1"));
    assert_eq!(value(direct, "thermometers_quiet"), Some("temp_machine"));
    assert_eq!(direct.level, rpkm_msgs::DiagnosticStatus::WARN);
}

/// The cell, started once the stack reads (its output lines in a thread).
fn cell_peer(py: &Path, script: &Path) -> (Proc, std::sync::mpsc::Receiver<String>) {
    let mut child = Command::new(py)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/joint_states_peer.py"))
        .arg(script)
        .args(["--domain", DOMAIN, "--timeout", "90"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("start joint_states_peer.py");
    let out = child.stdout.take().expect("piped");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            eprintln!("[cell] {line}");
            let _ = tx.send(line);
        }
    });
    (Proc(child), rx)
}

#[test]
fn a_cyclone_cell_drives_the_stack_as_the_csv_source_does() {
    let Some(py) = python() else { return };
    let c = campaign();
    let n = c.poses.len();
    let reference = reference();
    let (dir, launch) = launch_dir("js_cyc");
    let cell = cell();
    let script = Script {
        campaign: &c,
        cell: &cell,
        readers: 2,
        set_followers_on: &["/rpkm/ingest", DIRECT],
        poses: n,
        tail: true,
    };
    let script = write_script(&dir.0, &script.text());
    // the direct estimator reads the block's keys from a wildcard section
    let direct_params = dir.path("direct.yaml");
    std::fs::write(
        &direct_params,
        crate::joint_states_support::cell_block().replacen("ingest:", "/**:", 1),
    )
    .expect("direct.yaml");
    let prefix = unique("jscyc");
    let mut obs = Observer::new(
        &prefix,
        Some(("/direct/tcp_estimate", "/direct/diagnostics")),
    );
    let envs = [
        ("RPKM_IPC_PREFIX", prefix.as_str()),
        ("ROS_DOMAIN_ID", DOMAIN),
    ];
    let mut stack = Launch::start_with(&launch, &["source:=joint_states"], &envs);
    let direct_log = std::fs::File::create(dir.path("direct.log")).expect("log");
    let _direct = Proc(
        Command::new(rpkm())
            .args(["node", "tcp_estimator", "--backend", "ipc", "--params"])
            .arg(&direct_params)
            .args(["--param", "source=joint_states"])
            .args(["--param", "diagnostics_period_s=0.2"])
            .args(["--ros-args", "-r", "__ns:=/direct"])
            .envs(envs)
            .stderr(direct_log)
            .spawn()
            .expect("start the direct estimator"),
    );
    let (_peer, said) = cell_peer(&py, &script);
    obs.until(Duration::from_secs(90), |s| {
        s.estimates.len() > n
            && s.extra.len() > n
            && s.statuses.len() > n
            && s.diagnostics.get("rpkm/ingest").is_some_and(|d| {
                value(d, "rejected_non_finite") == Some("1")
                    && value(d, "thermometers_quiet") == Some("temp_machine")
            })
            && s.diagnostics
                .get("direct/tcp_estimator")
                .is_some_and(|d| value(d, "thermometers_quiet") == Some("temp_machine"))
    });
    let mut played = Vec::new();
    while let Ok(line) = said.recv_timeout(Duration::from_secs(30)) {
        let end = line.starts_with("PLAYED") || line.starts_with("TIMEOUT");
        played.push(line);
        if end {
            break;
        }
    }
    stack.stop();
    assert_eq!(
        played,
        [
            "SET followers ok",
            "SET followers ok",
            &format!("PLAYED {}", n + 4)
        ],
        "the cell's account"
    );
    let log = stack.log.lock().map(|l| l.join("\n")).unwrap_or_default();
    let seen = &obs.seen;

    // none lost, nothing published from the refused messages: the poses and the one after
    let seqs: Vec<u64> = seen.estimates.keys().copied().collect();
    assert_eq!(seqs, (1..=n as u64 + 1).collect::<Vec<_>>(), "estimates");
    assert_eq!(seen.states.len(), n + 1, "drive states published");
    assert_eq!(seen.extra.len(), n + 1, "the direct estimator's estimates");
    let [stack_gap, direct_gap, status_gap] = against_reference(seen, n);
    eprintln!(
        "largest gaps to the CSV source (m, N): estimates {stack_gap:?}, direct estimator \
         {direct_gap:?}, preload statuses {status_gap:?}"
    );
    for (what, (m, f)) in [
        ("estimates", stack_gap),
        ("direct estimates", direct_gap),
        ("preload statuses", status_gap),
    ] {
        assert!(m <= 1e-9 && f <= 1e-6, "{what}: {m} m, {f} N");
    }

    // the switch: from the first state after the set, in ingest's log and in the outputs
    let (first, q2_before, q2_after) = switch_of(seen);
    eprintln!(
        "followers switched at seq {first}: q2 current {q2_before} % (follower) -> \
         {q2_after} % (holding); x {} m (CSV {} m)",
        seen.estimates[&first].x, reference.estimates[&first].x
    );
    assert_eq!(first, split(&c) as u64 + 1, "the first state after the set");
    assert!(
        log.contains(&format!(
            "[ingest] followers 23 -> none from seq {first} on"
        )),
        "ingest's log: {log}"
    );
    let direct_said = std::fs::read_to_string(dir.path("direct.log")).unwrap_or_default();
    assert!(
        direct_said.contains(&format!("followers 23 -> none from seq {first} on")),
        "{direct_said}"
    );
    assert!(
        q2_before == 0.0 && q2_after.abs() > 1.0,
        "{q2_before} -> {q2_after} %"
    );
    // and the estimate is not the one q2, q3 as followers give (the core's solve of the same
    // drive state): the switch changed its drive forces (q3's preload) and the TCP
    let pose = &c.poses[split(&c)];
    let old = fegm(
        &Params::nominal(),
        &Stiffness::default(),
        pose.q,
        FOLLOWERS_23,
    )
    .expect("the core solves the state with q2, q3 following");
    let e = &seen.estimates[&first];
    let preload = (0..4)
        .map(|i| (e.drive_forces[i] - old.drive_force[i]).abs())
        .fold(0.0f64, f64::max);
    let moved = (e.x - old.x / 1e3).hypot(e.y - old.y / 1e3);
    eprintln!(
        "seq {first}: every drive holding: drive forces {:?} N, with q2, q3 following {:?} N \
         (TCP {moved:e} m apart)",
        e.drive_forces, old.drive_force
    );
    assert!(preload > 100.0 && moved > 1e-6, "{preload} N, {moved} m");

    // temperatures: named in the campaign info, attached, not measured once quiet
    let info = seen.info.as_ref().expect("campaign info");
    assert_eq!(info.covariate_names, ["temp_machine"]);
    // the thermometer's readings: at every 100th pose
    let temps: Vec<f64> = c
        .poses
        .iter()
        .step_by(100)
        .filter_map(|p| p.covariates[0])
        .collect();
    for s in &seen.states[..n] {
        assert!(
            temps.contains(&s.covariates[0]),
            "seq {}: {:?}",
            s.seq,
            s.covariates()
        );
    }
    assert!(seen.states[n].covariates[0].is_nan(), "after the silence");
    refusals_reported(seen);
    assert!(
        log.contains("WARN: thermometer temp_machine (/cell/frame_temperature) quiet for"),
        "{log}"
    );
}
