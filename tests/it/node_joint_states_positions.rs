//! Issue 51: a cell without force sensing gets its TCP estimate. The Cyclone DDS cell
//! (tests/python/joint_states_peer.py) plays the campaign of node_joint_states.rs (the demo's
//! drive states, then 100 poses of the twin under preload of kN, the follower switch between)
//! with its efforts left out: every other JointState with an empty `effort` array (as
//! sensor_msgs/JointState allows a joint without effort), the others with NaN efforts. The
//! shipped launch runs the stack with `source:=joint_states`. Checked against the same
//! campaign through the CSV source, efforts measured (`joint_states_support::reference`):
//!
//! - every pose estimated, each TcpEstimate equal to the CSV source's to 1e-9 m and 1e-6 N
//!   (its drive forces are the model's prediction): the estimate uses the positions alone;
//! - the drive states carry a holding drive's force NaN (not measured), a follower's 0;
//! - every PreloadStatus: the measured currents and deviations NaN where not measured, never
//!   0, the predicted currents and the followers' Δq the CSV source's, the level the Δq's
//!   alone (`debounce_samples: 1` here: each status's own), where the CSV source's forces
//!   raise WARN and ERROR;
//! - the preload monitor says on /diagnostics (not an alarm) and in its log why its currents
//!   are silent; ingest refused nothing.

use crate::joint_states_support::{
    campaign, cell, launch_dir, reference, split, value, write_script, Observed, Observer, Script,
};
use crate::node_support::{python, Launch, Proc};

use rpkm_msgs::{DiagnosticStatus, PreloadStatus};

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

const DOMAIN: &str = "69";

/// The cell's script with the efforts left out: the `k`-th JointState's effort list empty
/// for even `k`, NaN for odd `k`.
fn without_efforts(script: &str) -> String {
    let mut k = 0usize;
    let mut out = String::new();
    for line in script.lines() {
        let mut fields: Vec<String> = line.split(' ').map(String::from).collect();
        if fields[0] == "J" {
            let joints = fields[3].split(',').count();
            fields[6] = if k.is_multiple_of(2) {
                "-".to_owned()
            } else {
                vec!["nan"; joints].join(",")
            };
            k += 1;
        }
        out.push_str(&fields.join(" "));
        out.push('\n');
    }
    out
}

/// The level of the followers' Δq alone, by the shipped params.yaml's thresholds (50 µm,
/// 200 µm); OK where no drive follows (Δq NaN).
fn dq_level(st: &PreloadStatus) -> u8 {
    let dq = st.dq2.abs().max(st.dq3.abs());
    if dq >= 200e-6 {
        PreloadStatus::ERROR
    } else if dq >= 50e-6 {
        PreloadStatus::WARN
    } else {
        PreloadStatus::OK
    }
}

/// The largest gap (N) of the predicted currents of two statuses; the stamps and the
/// followers' Δq must agree, `got`'s level be its Δq's, its measured currents NaN for the
/// holding drives and 0 for the followers.
fn status_gap(got: &PreloadStatus, want: &PreloadStatus, follower: [bool; 4]) -> f64 {
    assert_eq!(got.stamp, want.stamp);
    assert_eq!(got.level, dq_level(got), "{got:?}");
    for (g, w) in [(got.dq2, want.dq2), (got.dq3, want.dq3)] {
        assert!(
            (g.is_nan() && w.is_nan()) || (g - w).abs() <= 1e-12,
            "Δq {g} vs {w}"
        );
    }
    let drives = got
        .measured_current
        .iter()
        .zip(&got.deviation)
        .zip(follower);
    for (i, ((&m, &d), follows)) in drives.enumerate() {
        if follows {
            assert!(m == 0.0, "a follower's current: {m} %");
        } else {
            assert!(m.is_nan() && d.is_nan(), "q{}: {m} %, {d} %", i + 1);
        }
    }
    let n_per_percent = rpkm_core::elastic::NOMINAL_DRIVE_FORCE_N / 100.0;
    got.predicted_current
        .iter()
        .zip(&want.predicted_current)
        .fold(0.0f64, |w, (a, b)| w.max((a - b).abs() * n_per_percent))
}

#[test]
fn a_cell_without_efforts_gets_every_pose_estimated() {
    let Some(py) = python() else { return };
    let c = campaign();
    let n = c.poses.len();
    // the CSV source's run first, not beside this one
    reference();
    let (dir, launch) = launch_dir("js_pos");
    each_status_its_own(&dir.path("test.yaml"));
    let cell = cell();
    let script = Script {
        campaign: &c,
        cell: &cell,
        readers: 1,
        set_followers_on: &["/rpkm/ingest"],
        poses: n,
        tail: false,
    };
    let script = write_script(&dir.0, &without_efforts(&script.text()));
    let prefix = crate::node_support::unique("jspos");
    let mut obs = Observer::new(&prefix, None);
    let envs = [
        ("RPKM_IPC_PREFIX", prefix.as_str()),
        ("ROS_DOMAIN_ID", DOMAIN),
    ];
    let mut stack = Launch::start_with(&launch, &["source:=joint_states"], &envs);
    let mut peer = Proc(
        Command::new(&py)
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/joint_states_peer.py"))
            .arg(&script)
            .args(["--domain", DOMAIN, "--timeout", "60"])
            .stdout(Stdio::piped())
            .spawn()
            .expect("start joint_states_peer.py"),
    );
    let monitor_said = |s: &Observed| {
        s.diagnostics
            .get("rpkm/preload_monitor")
            .and_then(|d| value(d, "forces_not_measured"))
            .is_some_and(|v| v == n.to_string())
    };
    obs.until(Duration::from_secs(60), |s| {
        s.estimates.len() >= n && s.statuses.len() >= n && monitor_said(s)
    });
    stack.stop();
    let mut played = String::new();
    if let Some(mut out) = peer.0.stdout.take() {
        let _ = std::io::Read::read_to_string(&mut out, &mut played);
    }
    assert!(played.contains(&format!("PLAYED {n}")), "{played}");
    let log = stack.log.lock().map(|l| l.join("\n")).unwrap_or_default();
    let seen = &obs.seen;
    estimates_as_with_efforts(seen, split(&c) as u64 + 1);
    states_not_measured(seen);
    preload_check(seen, &log);
}

/// The test's settings with the preload monitor's `debounce_samples: 1`: each status's level
/// its own sample's (the CSV source's hold 3).
fn each_status_its_own(test_yaml: &Path) {
    let settings = std::fs::read_to_string(test_yaml).expect("test.yaml");
    let settings = settings.replace(
        "    status_every: 1\n",
        "    status_every: 1\n    debounce_samples: 1\n",
    );
    assert!(settings.contains("debounce_samples: 1"), "{settings}");
    std::fs::write(test_yaml, settings).expect("test.yaml");
}

/// Every pose estimated, each as the CSV source's with its efforts; `twin`: the seq of the
/// first pose under preload.
fn estimates_as_with_efforts(seen: &Observed, twin: u64) {
    let want = reference();
    let n = want.estimates.len();
    assert_eq!(seen.estimates.len(), n, "estimates");
    let mut gap = (0.0f64, 0.0f64);
    for seq in 1..=n as u64 {
        let (m, f) =
            crate::joint_states_support::estimate_gap(&seen.estimates[&seq], &want.estimates[&seq]);
        gap = (gap.0.max(m), gap.1.max(f));
    }
    eprintln!("largest gap of the estimates to the CSV source (efforts measured): {gap:?} (m, N)");
    assert!(gap.0 <= 1e-9 && gap.1 <= 1e-6, "{gap:?}");
    // the twin's poses: drive forces of kN predicted, none measured
    let twin = &seen.estimates[&twin];
    assert!(
        twin.drive_forces.iter().any(|f| f.abs() > 100.0),
        "{twin:?}"
    );
}

/// The drive states: a holding drive's force not measured (NaN), a follower's 0.
fn states_not_measured(seen: &Observed) {
    assert_eq!(
        seen.states.len(),
        reference().estimates.len(),
        "drive states"
    );
    for s in &seen.states {
        for (i, (&f, follows)) in s.force.iter().zip(s.follower).enumerate() {
            assert!(
                if follows { f == 0.0 } else { f.is_nan() },
                "seq {}: f{} = {f}",
                s.seq,
                i + 1
            );
        }
    }
}

/// The preload check: predicted as with efforts, measured not, the level the Δq's; the
/// monitor says why on /diagnostics and in its `log`; ingest refused nothing.
fn preload_check(seen: &Observed, log: &str) {
    let want = reference();
    assert_eq!(seen.statuses.len(), want.statuses.len(), "preload statuses");
    let mut predicted = 0.0f64;
    for (k, (got, w)) in seen.statuses.iter().zip(&want.statuses).enumerate() {
        predicted = predicted.max(status_gap(got, w, seen.states[k].follower));
    }
    let raised = |statuses: &[PreloadStatus]| {
        statuses
            .iter()
            .filter(|p| p.level != PreloadStatus::OK)
            .count()
    };
    eprintln!(
        "largest gap of the predicted currents: {predicted} N; statuses above OK: {} (the \
         followers' Δq), the CSV source's {} (its forces too)",
        raised(&seen.statuses),
        raised(&want.statuses)
    );
    assert!(predicted <= 1e-6, "{predicted} N");
    let monitor = &seen.diagnostics["rpkm/preload_monitor"];
    eprintln!("preload_monitor /diagnostics: {}", monitor.message);
    assert_eq!(monitor.level, DiagnosticStatus::OK, "{}", monitor.message);
    assert!(
        monitor
            .message
            .contains("drive forces of q1, q2, q3, q4 not measured (a cell without force sensing)"),
        "{}",
        monitor.message
    );
    let told = log
        .lines()
        .filter(|l| l.contains("[preload_monitor]") && l.contains("not measured"))
        .count();
    assert!(told >= 1, "the monitor's log says why: {log}");
    let ingest = &seen.diagnostics["rpkm/ingest"];
    assert_eq!(
        value(ingest, "rejected_non_finite"),
        Some("0"),
        "{ingest:?}"
    );
    assert_eq!(value(ingest, "rejected_malformed"), Some("0"), "{ingest:?}");
}
