//! Issue 51: what a cell said survives a restart. The shipped launch runs the stack on a
//! ros2_control cell (an independent Eclipse Cyclone DDS peer, tests/python/
//! joint_states_peer.py) with the docs' cell block (`followers: "23"`). The cell switches its
//! controllers, every drive holding, and says so through ingest's parameter services
//! (`followers none`, the spelling the logs write; `''` reads the same); then ingest is killed with SIGKILL and the launch restarts it. The
//! restarted ingest must carry the value set, not the file's: its start-up line says it is
//! kept and when it was set, `get_parameters` returns it (tests/python/ros2_params_peer.py),
//! and every state of the twin's poses under preload the cell plays next carries every drive
//! holding; the preload monitor, on the twin's true geometry, finds every one OK (with q2, q3
//! taken for followers it does not: the false alarm of the issue).
//!
//! Needs the venv; without it SKIPPED, under RPKM_REQUIRE_PYTHON=1 a failure.

use crate::joint_states_support::{cell, joint_line, launch_dir, write_script, Observer};
use crate::node_support::{python, twin_stream, unique, write_truth_json, Launch, Proc};

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use rpkm_msgs::PreloadStatus;
use rpkm_nodes::campaign_bag::stamp_from_seconds;

const DOMAIN: &str = "67";
/// Poses the cell plays after the restart.
const POSES: usize = 100;

/// Runs a peer script to its end; its stdout.
fn run_peer(py: &Path, script: &str, args: &[&str]) -> String {
    let out = Command::new(py)
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/python")
                .join(script),
        )
        .args(args)
        .args(["--domain", DOMAIN, "--timeout", "30"])
        .output()
        .expect("run the peer");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    eprintln!("[{script}] {text}");
    assert!(out.status.success(), "{script}: {text}");
    text
}

#[test]
fn followers_set_at_run_time_survive_a_restart_of_ingest() {
    let Some(py) = python() else { return };
    let cell = cell();
    let (dir, launch) = launch_dir("kept");
    // the twin under preload, every drive holding, and its true geometry for every node: a
    // monitor that knows which drives hold finds the forces as the model predicts them
    let twin = twin_stream(POSES, 1000.0, |_| 0.0);
    let truth = dir.path("truth.json");
    write_truth_json(twin.twin.true_params(), &truth);
    std::fs::write(
        dir.path("test.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n    geometry_file: {}\n\
             ingest:\n  ros__parameters:\n    end_marker: false\n\
             preload_monitor:\n  ros__parameters:\n    status_every: 1\n",
            truth.display()
        ),
    )
    .expect("test.yaml");
    let prefix = unique("kept");
    let mut obs = Observer::new(&prefix, None);
    let envs = [
        ("RPKM_IPC_PREFIX", prefix.as_str()),
        ("ROS_DOMAIN_ID", DOMAIN),
    ];
    let mut stack = Launch::start_with(&launch, &["source:=joint_states"], &envs);
    let first = stack.wait_for("[ingest] source joint_states", Duration::from_secs(30));
    assert!(
        first.contains("followers 23 (from the parameter files)")
            && first.contains("joints q1_joint, q2_joint, q3_joint, q4_joint")
            && first.contains("thermometers temp_machine (/cell/frame_temperature)"),
        "{first}"
    );
    let set = write_script(
        &dir.0,
        "MATCH 1 /joint_states\nSET /rpkm/ingest followers none\n",
    );
    let said = run_peer(&py, "joint_states_peer.py", &[set.to_str().expect("utf-8")]);
    assert!(said.contains("SET followers ok"), "{said}");
    stack.wait_for(
        "[ingest] parameters set: followers",
        Duration::from_secs(10),
    );

    let pid = stack.started("ingest")[0];
    let killed = Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status()
        .expect("kill");
    assert!(killed.success());
    let again = stack.wait_for("[ingest] source joint_states", Duration::from_secs(30));
    assert_eq!(stack.started("ingest").len(), 2, "restarted by the launch");
    assert!(
        again.contains("followers none (kept from the run before the restart, set at 20"),
        "{again}"
    );

    let get = dir.path("get.json");
    std::fs::write(
        &get,
        r#"[{"get": ["followers", "temperatures.temp_machine"]}]"#,
    )
    .expect("get script");
    let got = run_peer(
        &py,
        "ros2_params_peer.py",
        &[get.to_str().expect("utf-8"), "--node", "/rpkm/ingest"],
    );
    let got: serde_json::Value = serde_json::from_str(got.trim()).expect("one JSON line");
    // the value as the cell set it: `none`, which every reader takes as `""`
    assert_eq!(got["get"]["followers"], serde_json::json!([4, "none"]));
    // the thermometer map, a group, is listed entry by entry
    assert_eq!(
        got["get"]["temperatures.temp_machine"],
        serde_json::json!([4, "/cell/frame_temperature"])
    );

    // the twin's poses: the cell plays them to the restarted node
    let mut script = String::from("MATCH 1 /joint_states\n");
    for pose in &twin.campaign.poses {
        let stamp = stamp_from_seconds(pose.t).expect("a stamp");
        let q = pose.q.map(|q| q / rpkm_nodes::units::MM_PER_M);
        script.push_str(&joint_line(&cell, stamp, q, pose.f));
    }
    let play = write_script(&dir.0, &script);
    let _player = Proc(
        Command::new(&py)
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/joint_states_peer.py"))
            .arg(&play)
            .args(["--domain", DOMAIN, "--timeout", "30"])
            .spawn()
            .expect("start the cell"),
    );
    let n = POSES;
    obs.until(Duration::from_secs(30), |s| s.statuses.len() >= n);
    stack.stop();
    let seen = &obs.seen;
    assert_eq!(seen.states.len(), n, "every pose played after the restart");
    let followers: Vec<[bool; 4]> = seen.states.iter().map(|s| s.follower).collect();
    assert!(
        followers.iter().all(|f| *f == [false; 4]),
        "the states after the restart carry every drive holding: {:?}",
        &followers[..3]
    );
    let levels: Vec<u8> = seen.statuses.iter().map(|s| s.level).collect();
    eprintln!("preload levels after the restart: {levels:?}");
    assert_eq!(seen.statuses.len(), n);
    assert!(
        levels.iter().all(|&l| l == PreloadStatus::OK),
        "no preload alarm from the restart"
    );
}
