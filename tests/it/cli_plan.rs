//! `rpkm plan` and `rpkm simulate --plan` end to end: a plan written, measured on the twin and
//! read back as a campaign; its drive mode the campaign's unless the model carries the
//! preload; what it buys per budget in words; a drifting tracker's return reported by
//! `rpkm calibrate`; bad arguments and a bad PLAN.csv exit 2 naming what is wrong.

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

/// `rpkm simulate --campaign CAMPAIGNS --seed SEED [extra]` into `dir/name`, no held-out
/// file; its path.
fn simulated(dir: &Path, name: &str, (campaigns, seed): (&str, &str), extra: &[&str]) -> String {
    let out = path(dir, name);
    let mut args = vec![
        "simulate",
        "--campaign",
        campaigns,
        "--seed",
        seed,
        "--validation",
        "0",
        "--out",
        &out,
    ];
    args.extend_from_slice(extra);
    let (code, _, err) = rpkm(&args);
    assert_eq!(code, Some(0), "{args:?}: {err}");
    out
}

#[test]
fn a_plan_is_written_measured_on_the_twin_and_read_back() {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let campaign = simulated(dir.path(), "self.csv", ("self", "3"), &[]);
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
    assert!(out.contains("12 random poses instead"), "{out}");
    let text = std::fs::read_to_string(&plan).expect("PLAN.csv");
    let rows = plan_rows(&text);
    assert_eq!(rows.len(), 12, "{text}");
    // a self-calibration base and no preload in the model: q2, q3 follow
    assert_eq!(rows[0], "plan_lt,lt,1,23,0,1700", "the reset first: {text}");
    assert_eq!(
        rows[11], "plan_lt,lt,0,23,0,1700",
        "the return last: {text}"
    );
    assert!(text.contains("# drives: external instruments measure with q2, q3 following"));
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

/// The pose rows of a PLAN.csv (no comment, no header).
fn plan_rows(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .collect()
}

fn json(path: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("JSON")).expect("JSON")
}

/// A twin measured with all four drives active (the preload deflects it, the forces
/// recorded): the plan's tracker rows keep that mode whether or not the model carries the
/// preload, and say which; without it they warn that the poses carry a deflection the model
/// cannot represent. A campaign whose tracker rows had q2, q3 following plans them so, and
/// `--follower` names another mode.
#[test]
fn the_plan_measures_in_the_campaigns_drive_mode_unless_the_model_carries_the_preload() {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let preload = ["--effect", "preload_elastic"];
    let loaded = simulated(dir.path(), "loaded.csv", ("lt,self", "4"), &preload);
    let following = simulated(dir.path(), "following.csv", ("lt,self", "4"), &[]);
    let cases: [(&str, &[&str], &str, &str); 6] = [
        (&loaded, &[], "", "the model carries no preload"),
        (
            &loaded,
            &["--effects", "preload_elastic"],
            "",
            "the model carries preload_elastic and the campaign recorded the drive forces",
        ),
        (
            &following,
            &[],
            "23",
            "as 45 of the campaign's 45 external rows",
        ),
        (&loaded, &["--follower", "23"], "23", "as --follower names"),
        // no follower, in either spelling every reader of followers takes
        (
            &following,
            &["--follower", "none"],
            "",
            "as --follower names",
        ),
        (&following, &["--follower", ""], "", "as --follower names"),
    ];
    for (k, (campaign, extra, want, why)) in cases.into_iter().enumerate() {
        let plan = path(dir.path(), &format!("plan{k}.csv"));
        let mut args = vec!["plan", campaign, "--budget", "4", "--out", &plan];
        args.extend_from_slice(extra);
        let (code, out, err) = rpkm(&args);
        assert_eq!(code, Some(0), "{args:?}: {err}");
        assert!(out.contains(why), "{args:?}: {out}");
        let text = std::fs::read_to_string(&plan).expect("PLAN.csv");
        for row in plan_rows(&text) {
            let follower = row.split(',').nth(3).expect("a follower column");
            assert_eq!(follower, want, "{args:?}: {text}");
        }
    }
}

/// Several budgets: a table of the expected held-out RMS after the plan and after as many
/// random poses, falling with the budget, the JSON with each; a budget too small to buy
/// anything with the tracker says so and names the instruments that would.
#[test]
fn the_summary_says_what_each_budget_buys() {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let base = simulated(dir.path(), "self.csv", ("self", "3"), &[]);
    let j = path(dir.path(), "plan.json");
    let (code, out, err) = rpkm(&[
        "plan", &base, "--budget", "3,5,10", "--noise", "lt=0.005", "--json", &j,
    ]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("by budget"), "{out}");
    assert!(out.contains("the plan lowers the TCP's own error"), "{out}");
    let v = json(&j);
    let budgets = v["budgets"].as_array().expect("budgets");
    assert_eq!(budgets.len(), 3);
    let after: Vec<f64> = budgets
        .iter()
        .map(|b| b["after_um"].as_f64().expect("after"))
        .collect();
    assert!(after[0] > after[1] && after[1] > after[2], "{after:?}");
    let now = v["now_um"].as_f64().expect("now");
    let floor = v["floor_um"].as_f64().expect("floor");
    assert!(
        now > after[0] && after[2] > floor,
        "{now} {after:?} {floor}"
    );
    assert_eq!(v["drive_mode"]["follower"], "23");
    // a production path of six poses: the TCP judged there
    let way = path(dir.path(), "path.csv");
    std::fs::write(
        &way,
        "x,y\n-100,1000\n0,1000\n100,1000\n-100,1100\n0,1100\n100,1100\n",
    )
    .expect("written");
    let (code, out, err) = rpkm(&["plan", &base, "--budget", "5", "--where", &way]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("a tracker setup at the 6 poses of"), "{out}");
    // lt and self measured already: 3 tracker poses add nothing, another instrument would
    let full = simulated(dir.path(), "ltself.csv", ("lt,self", "4"), &[]);
    let (code, out, err) = rpkm(&["plan", &full, "--budget", "3"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("the plan buys nothing"), "{out}");
    assert!(
        out.contains("nothing to gain with lt in 3 poses; try --instruments"),
        "{out}"
    );
}

/// A tracker creeping 20 µm/min after its zero measures a plan: `rpkm calibrate` reports
/// the setup's return as moved, by the drift the twin put in (within 3σ), in its text and
/// its JSON; the same plan from a tracker that does not drift returns within its noise.
#[test]
fn calibrate_reports_a_drifting_trackers_return() {
    let dir = tempfile::tempdir().expect("a scratch folder");
    let base = simulated(dir.path(), "self.csv", ("self", "5"), &[]);
    let plan = path(dir.path(), "plan.csv");
    let (code, _, err) = rpkm(&["plan", &base, "--budget", "20", "--out", &plan]);
    assert_eq!(code, Some(0), "{err}");
    for (drift, moved) in [("lt=0,20", true), ("lt=0,0", false)] {
        let measured = path(dir.path(), "measured.csv");
        let (code, _, err) = rpkm(&[
            "simulate", "--plan", &plan, "--seed", "5", "--noise", "lt=0.001", "--drift", drift,
            "--out", &measured,
        ]);
        assert_eq!(code, Some(0), "{err}");
        let cal = path(dir.path(), "cal.json");
        let (code, out, err) = rpkm(&[
            "calibrate",
            &measured,
            "--noise",
            "lt=0.001",
            "--json",
            &cal,
        ]);
        assert_eq!(code, Some(0), "{err}");
        let r = &json(&cal)["returns"][0];
        assert_eq!(r["setup"], "plan_lt", "{r}");
        let seconds = r["seconds"].as_f64().expect("seconds");
        let y = &r["components"][1];
        let want = if moved { 20e-3 / 60.0 * seconds } else { 0.0 };
        let (value, sigma) = (
            y["value_mm"].as_f64().expect("value"),
            y["sigma_mm"].as_f64().expect("sigma"),
        );
        assert!((value - want).abs() < 3.0 * sigma, "{value} {want} {sigma}");
        let said = if moved {
            "lt setup plan_lt moved"
        } else {
            "lt setup plan_lt returned within its noise"
        };
        assert!(out.contains(said), "{drift}: {out}");
    }
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
        vec!["plan", campaign.as_str(), "--budget", "5,0"],
        vec!["plan", campaign.as_str(), "--criterion", "volume"],
        vec!["plan", campaign.as_str(), "--follower", "25x"],
        vec!["plan", campaign.as_str(), "--effects", "no_such_effect"],
        vec!["plan", campaign.as_str(), "--where", "/no/such/path.csv"],
    ] {
        let (code, _, err) = rpkm(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
    }
}
