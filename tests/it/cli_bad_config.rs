//! Configuration that cannot be used and output nobody reads end the command cleanly: no
//! panic (exit 101), no abort. Out-of-range durations and buffer sizes are bad input (exit 2)
//! naming the key and the file; a closed stdout pipe ends a report quietly.

use std::io::Read;
use std::path::Path;
use std::process::{Command, Output, Stdio};

fn rpkm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rpkm"))
}

fn run(cmd: &mut Command) -> (Option<i32>, String) {
    let Output { status, stderr, .. } = cmd.output().expect("run rpkm");
    (status.code(), String::from_utf8_lossy(&stderr).into_owned())
}

fn demo_campaign() -> &'static Path {
    Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/bags/demo/campaign.csv"
    ))
}

#[test]
fn calibrate_into_a_closed_pipe_ends_quietly() {
    let mut child = rpkm()
        .arg("calibrate")
        .arg(demo_campaign())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn rpkm calibrate");
    // The reader goes away before the report is written (the calibration takes a while),
    // as `| head -1` does after its line: every write then meets a closed pipe.
    drop(child.stdout.take());
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .expect("stderr")
        .read_to_string(&mut stderr)
        .expect("read stderr");
    let status = child.wait().expect("wait");
    assert_ne!(status.code(), Some(101), "panicked: {stderr}");
    assert!(
        !stderr.contains("panicked") && !stderr.contains("Broken pipe"),
        "{stderr}"
    );
}

#[test]
fn respawn_delay_1e308_is_rejected_with_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("bad.launch.yaml");
    std::fs::write(
        &file,
        "launch:\n  - node: {pkg: rpkm, exec: calibrator, respawn: true, respawn_delay: 1e308}\n",
    )
    .expect("write launch file");
    let (code, stderr) = run(rpkm().arg("launch").arg(&file));
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("respawn_delay"), "{stderr}");
    assert!(stderr.contains(&file.display().to_string()), "{stderr}");
    assert!(
        !stderr.contains("[launch] started"),
        "nothing is started: {stderr}"
    );
}

#[test]
fn launch_rejects_unknown_keys_with_the_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("typo.launch.yaml");
    std::fs::write(
        &file,
        "launch:\n  - executable:\n      cmd: rpkm record\n      If: \"false\"\n",
    )
    .expect("write launch file");
    let (code, stderr) = run(rpkm().arg("launch").arg(&file));
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{}:4: executable: unknown key \"If\"",
            file.display()
        )),
        "{stderr}"
    );
}

#[test]
fn launch_does_not_respawn_a_node_with_a_bad_configuration_and_exits_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(
        dir.path().join("params.yaml"),
        "calibrator:\n  ros__parameters:\n    state_buffer: 4294967296\n",
    )
    .expect("write params");
    let file = dir.path().join("bad.launch.yaml");
    std::fs::write(
        &file,
        "launch:\n  - node: {pkg: rpkm, exec: calibrator, param: [{from: params.yaml}], \
         args: --backend ipc, respawn: true, respawn_delay: 0.0}\n",
    )
    .expect("write launch file");
    let prefix = format!("rpkm_badcfg_{}_launch", std::process::id());
    let (code, stderr) = run(rpkm()
        .arg("launch")
        .arg(&file)
        .env("RPKM_IPC_PREFIX", prefix));
    assert_eq!(code, Some(2), "{stderr}");
    assert_eq!(
        stderr.matches("[launch] started calibrator").count(),
        1,
        "not restarted: {stderr}"
    );
    assert!(stderr.contains("state_buffer"), "{stderr}");
    assert!(
        stderr.contains("failed their configuration (exit 2, not restarted): calibrator"),
        "{stderr}"
    );
}

/// Runs `rpkm node EXEC` with the parameter file `yaml`; returns the exit code and stderr.
fn node_with_params(exec: &str, yaml: &str) -> (Option<i32>, String, String) {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("params.yaml");
    std::fs::write(&file, yaml).expect("write params");
    let prefix = format!("rpkm_badcfg_{}_{exec}", std::process::id());
    let (code, stderr) = run(rpkm()
        .args(["node", exec, "--backend", "ipc", "--params"])
        .arg(&file)
        .env("RPKM_IPC_PREFIX", prefix));
    (code, stderr, file.display().to_string())
}

#[test]
fn state_buffer_4294967296_is_rejected() {
    let (code, stderr, file) = node_with_params(
        "calibrator",
        "calibrator:\n  ros__parameters:\n    state_buffer: 4294967296\n",
    );
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "{file}: calibrator/ros__parameters/state_buffer: 4294967296 is out of range"
        )),
        "{stderr}"
    );
}

#[test]
fn durations_and_rates_beyond_their_bounds_are_rejected_with_the_key() {
    for (exec, key, value) in [
        ("calibrator", "idle_end_s", "1e308"),
        ("calibrator", "diagnostics_period_s", "1e308"),
        ("tcp_estimator", "busy_poll_ms", "1e308"),
        ("preload_monitor", "busy_poll_ms", "1e308"),
        ("ingest", "start_delay_s", "1e308"),
        ("ingest", "rate_hz", "1e-300"),
    ] {
        let (code, stderr, file) = node_with_params(
            exec,
            &format!("{exec}:\n  ros__parameters:\n    {key}: {value}\n"),
        );
        assert_eq!(code, Some(2), "{exec} {key}: {stderr}");
        assert!(
            stderr.contains(&format!("{file}: {exec}/ros__parameters/{key}: ")),
            "{exec} {key}: {stderr}"
        );
        assert!(stderr.contains("out of range"), "{exec} {key}: {stderr}");
    }
}

#[test]
fn counts_and_priorities_beyond_their_bounds_are_rejected_with_the_key() {
    for (exec, key, value, range) in [
        // 0 was silently taken as 1, 2^32 silently clamped.
        (
            "preload_monitor",
            "status_every",
            "0",
            "expected 1 to 1000000",
        ),
        (
            "preload_monitor",
            "debounce_samples",
            "0",
            "expected 1 to 1000000",
        ),
        (
            "preload_monitor",
            "debounce_samples",
            "4294967296",
            "expected 1 to 1000000",
        ),
        (
            "calibrator",
            "calibrate_every",
            "18446744073709551615",
            "expected 0 to 1000000",
        ),
        // A negative threshold silently meant "no outlier removal".
        ("calibrator", "outlier_sigma", "-3", "expected 0 to 100 σ"),
        // An invalid priority was logged and the node ran at normal priority.
        ("tcp_estimator", "rt_priority", "100", "expected 0 to 99"),
    ] {
        let (code, stderr, file) = node_with_params(
            exec,
            &format!("{exec}:\n  ros__parameters:\n    {key}: {value}\n"),
        );
        assert_eq!(code, Some(2), "{exec} {key}: {stderr}");
        assert!(
            stderr.contains(&format!(
                "{file}: {exec}/ros__parameters/{key}: {value} is out of range: {range}"
            )),
            "{exec} {key}: {stderr}"
        );
    }
}
