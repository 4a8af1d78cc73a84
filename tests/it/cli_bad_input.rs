//! Bad campaign input ends `rpkm calibrate`, `rpkm diagnose` and `rpkm node ingest` with
//! exit code 2 (the ingest node: a logged reject) and a message naming the file, line and
//! column (or byte offset) and what was expected. The cases found from outside the project
//! (issue 16), each by name.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn demo(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("bags/demo")
        .join(name)
}

/// The demo file `name` with field `column` (1-based) of line `line` set to `value`, written
/// into `dir`.
fn edited(dir: &Path, name: &str, line: usize, column: usize, value: &str) -> PathBuf {
    let text = std::fs::read_to_string(demo(name)).expect("demo campaign");
    let mut out = String::new();
    for (i, l) in text.lines().enumerate() {
        if i + 1 == line {
            let mut fields: Vec<&str> = l.split(',').collect();
            fields[column - 1] = value;
            out += &fields.join(",");
        } else {
            out += l;
        }
        out.push('\n');
    }
    let path = dir.join(format!("{line}_{column}_{name}"));
    std::fs::write(&path, out).expect("write campaign");
    path
}

/// Runs rpkm with `args`; (exit code, stderr).
fn rpkm(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args(args)
        .output()
        .expect("run rpkm");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn calibrate(file: &Path) -> (Option<i32>, String) {
    rpkm(&["calibrate", &file.display().to_string()])
}

#[test]
fn a_self_calibration_row_with_minus_1e300_exits_2_naming_line_and_column() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = edited(dir.path(), "campaign.csv", 48, 6, "-1e300");
    let (code, stderr) = calibrate(&file);
    assert_eq!(code, Some(2), "{stderr}");
    assert_eq!(
        stderr.trim_end(),
        format!(
            "error: {}:48:6 (q2): -1e300 mm is beyond any machine, expected |q2| <= 100000 mm",
            file.display()
        )
    );
}

#[test]
fn nan_and_inf_exit_2_naming_line_and_column() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (column, text) in [(5, "nan"), (9, "inf"), (14, "-inf"), (18, "NaN")] {
        let file = edited(dir.path(), "campaign.csv", 7, column, text);
        let (code, stderr) = calibrate(&file);
        assert_eq!(code, Some(2), "{stderr}");
        assert!(
            stderr.contains(&format!("{}:7:{column} (", file.display()))
                && stderr.contains(&format!("expected a finite number, found \"{text}\"")),
            "{stderr}"
        );
    }
}

#[test]
fn a_309_digit_number_is_printed_short() {
    let dir = tempfile::tempdir().expect("tempdir");
    let digits = format!("1{}", "0".repeat(308));
    let file = edited(dir.path(), "campaign.csv", 7, 5, &digits);
    let (code, stderr) = calibrate(&file);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains(":7:5 (q1): 1e308 mm is beyond any machine"),
        "{stderr}"
    );
    assert!(stderr.len() < 200, "{stderr}");
}

#[test]
fn an_unreachable_row_of_a_validate_file_exits_2_naming_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let val = edited(dir.path(), "campaign.val.csv", 5, 5, "9000");
    let campaign = demo("campaign.csv").display().to_string();
    let val_arg = val.display().to_string();
    for command in ["calibrate", "diagnose"] {
        let (code, stderr) = rpkm(&[command, &campaign, "--validate", &val_arg]);
        assert_eq!(code, Some(2), "{command}: {stderr}");
        assert!(
            stderr.contains(&format!(
                "{val_arg}:5:5 (q1): unreachable pose, with q1 = 9000 mm"
            )),
            "{command}: {stderr}"
        );
    }
}

#[test]
fn an_unreachable_reset_pose_is_blamed_on_its_own_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Line 3 is the laser tracker's reset pose; q4 = -5000 mm puts rod 4 out of reach.
    let file = edited(dir.path(), "campaign.csv", 3, 8, "-5000");
    for command in ["calibrate", "diagnose"] {
        let (code, stderr) = rpkm(&[command, &file.display().to_string()]);
        assert_eq!(code, Some(2), "{command}: {stderr}");
        assert!(
            stderr.contains(&format!("{}:3:8 (q4): unreachable pose", file.display())),
            "{command}: {stderr}"
        );
    }
}

#[test]
fn invalid_utf8_names_line_and_byte_offset() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut bytes = std::fs::read(demo("campaign.csv")).expect("demo campaign");
    let line4: usize = bytes
        .split(|&b| b == b'\n')
        .take(3)
        .map(|l| l.len() + 1)
        .sum();
    bytes[line4 + 2] = 0xff;
    let file = dir.path().join("latin1.csv");
    std::fs::write(&file, &bytes).expect("write");
    let (code, stderr) = calibrate(&file);
    assert_eq!(code, Some(2), "{stderr}");
    assert_eq!(
        stderr.trim_end(),
        format!(
            "error: {}:4: invalid UTF-8 at byte {} of the file (byte 3 of the line), expected UTF-8 text",
            file.display(),
            line4 + 2
        )
    );
}

#[test]
fn reset_true_is_rejected_by_calibrate_and_ingest_alike() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = edited(dir.path(), "campaign.csv", 12, 4, "true");
    let (code, stderr) = calibrate(&file);
    assert_eq!(code, Some(2), "{stderr}");
    let expected = format!(
        "{}:12:4 (reset): expected 0 or 1, found \"true\"",
        file.display()
    );
    assert_eq!(stderr.trim_end(), format!("error: {expected}"));
    let bytes = std::fs::read(&file).expect("read back");
    for source in [file.display().to_string(), "stdin".to_owned()] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_rpkm"))
            .args(["node", "ingest", "--source", &source, "--backend", "ipc"])
            .args([
                "--ipc-prefix",
                &format!("t_reset_true_{}", std::process::id()),
            ])
            .args(["--param", "start_delay_s=0", "--param", "exit_at_end=true"])
            .args(["--param", "rate_hz=1e6"])
            .stdin(Stdio::piped())
            .stderr(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .expect("start ingest");
        let mut stdin = child.stdin.take().expect("stdin");
        if source == "stdin" {
            stdin.write_all(&bytes).expect("feed");
        }
        drop(stdin);
        let out = child.wait_with_output().expect("ingest ends");
        let log = String::from_utf8_lossy(&out.stderr);
        let rejects: Vec<&str> = log
            .lines()
            .filter_map(|l| l.strip_prefix("[ingest] rejected: "))
            .collect();
        let want = expected.replace(
            &file.display().to_string(),
            if source == "stdin" { "stdin" } else { &source },
        );
        assert_eq!(rejects, [want.as_str()], "{log}");
        assert!(
            log.contains("193 states"),
            "the other rows go through: {log}"
        );
    }
}

#[test]
fn diagnose_on_unreachable_poses_exits_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let file = edited(dir.path(), "campaign.csv", 5, 5, "9000");
    let (code, stderr) = rpkm(&["diagnose", &file.display().to_string()]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!("{}:5:5 (q1): unreachable pose", file.display())),
        "{stderr}"
    );
}

/// A production stream's crash and commanded motion (`rpkm simulate --production-step`,
/// `--production-visit`) that cannot be read exit 2 saying what was expected, and write no
/// stream.
#[test]
fn a_bad_production_step_or_motion_exits_2_saying_what_was_expected() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("prod.csv");
    let out = out.display().to_string();
    let cases: [(&str, &str, &str); 7] = [
        (
            "--production-step",
            "l3=0.1",
            "expected PARAM=CHANGE@SECONDS",
        ),
        ("--production-step", "l9=0.1@5", "unknown parameter `l9`"),
        ("--production-visit", "-150,2000", "no @SECONDS"),
        (
            "--production-visit",
            "-150,2000@soon",
            "SECONDS is not a number",
        ),
        (
            "--production-visit",
            "-150;2000@5",
            "pose 1 `-150` is not X,Y",
        ),
        (
            "--production-visit",
            "-150,2000;150,x@5",
            "pose 2 `150,x` is not two numbers",
        ),
        (
            "--production-visit",
            "-150,2000;900,1500@5",
            "pose 2 (900, 1500) is outside the workspace",
        ),
    ];
    for (flag, value, said) in cases {
        let arg = format!("{flag}={value}");
        let (code, stderr) = rpkm(&[
            "simulate",
            "--production-seconds",
            "2",
            &arg,
            "--production-decimate",
            "100",
            "--out",
            &out,
        ]);
        assert_eq!(code, Some(2), "{arg}: {stderr}");
        assert!(stderr.contains(said), "{arg}: {stderr}");
        assert!(!Path::new(&out).exists(), "{arg}: a stream was written");
    }
    // the motion needs a production stream
    let (code, stderr) = rpkm(&[
        "simulate",
        "--campaign",
        "lt",
        "--production-visit=-150,2000@5",
        "--out",
        &out,
    ]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--production-seconds"), "{stderr}");
}
