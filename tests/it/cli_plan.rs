//! `rpkm plan` and `rpkm simulate --plan` end to end: a plan written, measured on the twin and
//! read back as a campaign; bad arguments and a bad PLAN.csv exit 2 naming what is wrong.

use std::path::Path;
use std::process::Command;

fn rpkm(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args(args)
        .output()
        .expect("rpkm runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).display().to_string()
}

#[test]
fn a_plan_is_written_measured_on_the_twin_and_read_back() {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let campaign = path(dir.path(), "self.csv");
    let (code, _, err) = rpkm(&[
        "simulate",
        "--campaign",
        "self",
        "--seed",
        "3",
        "--validation",
        "0",
        "--out",
        &campaign,
    ]);
    assert_eq!(code, Some(0), "{err}");
    let plan = path(dir.path(), "plan.csv");
    let json = path(dir.path(), "plan.json");
    let (code, out, err) = rpkm(&[
        "plan",
        &campaign,
        "--model",
        "24",
        "--instruments",
        "lt",
        "--budget",
        "12",
        "--out",
        &plan,
        "--json",
        &json,
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("after the plan"), "{out}");
    let text = std::fs::read_to_string(&plan).expect("PLAN.csv");
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .collect();
    assert_eq!(rows.len(), 12, "{text}");
    assert!(
        rows[0].starts_with("plan_lt,lt,1,,"),
        "the reset first: {text}"
    );
    let measured = path(dir.path(), "measured.csv");
    let (code, _, err) = rpkm(&[
        "simulate", "--plan", &plan, "--seed", "3", "--out", &measured,
    ]);
    assert_eq!(code, Some(0), "{err}");
    let c = rpkm_core::campaign::Campaign::parse(
        &std::fs::read_to_string(&measured).expect("measured"),
        "measured.csv",
    )
    .expect("a campaign");
    assert_eq!(c.poses.len(), 12);
    let (code, _, err) = rpkm(&["calibrate", &measured, "--model", "24"]);
    assert_eq!(code, Some(0), "the measured plan calibrates: {err}");
}

#[test]
fn bad_plans_and_arguments_exit_2() {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let plan = path(dir.path(), "bad.csv");
    std::fs::write(
        &plan,
        "setup,instrument,reset,follower,x,y\ns,lt,1,,0,1700\ns,lt,0,,0,9000\n",
    )
    .expect("written");
    let out = path(dir.path(), "m.csv");
    let (code, _, err) = rpkm(&["simulate", "--plan", &plan, "--out", &out]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("bad.csv:3:5"), "{err}");
    let campaign = Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/demo/campaign.csv");
    let campaign = campaign.display().to_string();
    for args in [
        vec!["plan", campaign.as_str(), "--separate", "dir_q2"],
        vec!["plan", campaign.as_str(), "--separate", "dir_q2,dir_q9"],
        vec!["plan", campaign.as_str(), "--instruments", "li_x"],
        vec!["plan", campaign.as_str(), "--budget", "0"],
    ] {
        let (code, _, err) = rpkm(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
    }
}
