//! Effects files (`--effects-file`, docs/effects.md): a bad file ends `rpkm diagnose` and
//! `rpkm calibrate` with exit code 2 and a message naming the file, line and column of the
//! mistake and what is wrong, never a panic; a good one's effect is offered, fitted and
//! reported (the foreign simulator's cyclic scale error, found by the effect the issue
//! writes for it).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::foreign_support;

fn demo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("bags/demo/campaign.csv")
}

/// A good effect, each malformed case changes one thing of it.
const GOOD: &str = "effects:
  - name: cyclic_q4
    summary: pitch error of carrier 4's scale
    params: {a: {unit: mm, prior: 0.005}, c: {unit: mm, prior: 0.005}}
    dq4: \"a * sin(2*pi*q4/60) + c * cos(2*pi*q4/60)\"
";

/// (what, file text, line, column, words the message must hold).
const CASES: [(&str, &str, usize, usize, &str); 34] = [
    ("unclosed flow list", "effects: [\n", 2, 1, "not YAML"),
    ("bad indentation", "effects:\n  - name: a\n   summary: b\n", 3, 11, "not YAML"),
    ("empty file", "", 1, 1, "expected a mapping"),
    ("top level is a list", "- a\n", 1, 1, "expected a mapping"),
    ("unknown top key", "effect:\n  - name: a\n", 1, 1, "unknown key `effect`"),
    ("effects not a list", "effects: 3\n", 1, 10, "must be a list"),
    ("effects empty", "effects: []\n", 1, 10, "is empty"),
    ("effect not a mapping", "effects:\n  - foo\n", 2, 5, "must be a mapping"),
    ("no name", "effects:\n  - summary: s\n    dq4: \"q4\"\n", 2, 5, "no `name`"),
    ("no summary", "effects:\n  - name: e1\n    dq4: \"1e-3\"\n", 2, 11, "no `summary`"),
    ("name not a word", "effects:\n  - name: a b\n    summary: s\n    dq4: \"1e-3\"\n", 2, 11, "must be a word"),
    ("library name", "effects:\n  - name: thermal\n    summary: s\n    dq4: \"1e-3\"\n", 2, 11, "the library's effect"),
    (
        "two effects with one name",
        "effects:\n  - name: e1\n    summary: s\n    dq4: \"1e-3\"\n  - name: e1\n    summary: t\n    dq1: \"1e-3\"\n",
        5,
        11,
        "a second effect named `e1`",
    ),
    ("key twice", "effects:\n  - name: e1\n    name: e2\n", 3, 5, "given twice"),
    ("params not a mapping", "effects:\n  - name: e1\n    summary: s\n    params: [a]\n", 4, 13, "params: expected a mapping"),
    ("parameter without prior", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm}}\n    dq4: \"a\"\n", 4, 14, "has no `prior`"),
    ("parameter without unit", "effects:\n  - name: e1\n    summary: s\n    params: {a: {prior: 0.1}}\n    dq4: \"a\"\n", 4, 14, "has no `unit`"),
    ("prior not a number", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: big}}\n    dq4: \"a\"\n", 4, 35, "prior: expected a number"),
    ("prior negative", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: -1}}\n    dq4: \"a\"\n", 4, 14, "positive"),
    ("bounds of one number", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1, bounds: [1]}}\n    dq4: \"a\"\n", 4, 46, "bounds: expected [lower, upper]"),
    ("bounds reversed", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1, bounds: [1, 0]}}\n    dq4: \"a\"\n", 4, 14, "the lower first"),
    ("parameter named like a variable", "effects:\n  - name: e1\n    summary: s\n    params: {q4: {unit: mm, prior: 1}}\n    dq4: \"q4\"\n", 4, 14, "variable's or a function's"),
    ("parameter unknown key", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prio: 1}}\n    dq4: \"a\"\n", 4, 28, "unknown key `prio`"),
    ("target that does not exist", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dz: \"a\"\n", 5, 5, "unknown target `dz`"),
    ("parameter target that does not exist", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dp.l9: \"a\"\n", 5, 5, "unknown target `dp.l9`"),
    ("one target twice", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dp.g1: \"a\"\n    dp.gamma1: \"a\"\n", 6, 5, "given twice"),
    ("no expression", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n", 2, 11, "no expression"),
    ("expression syntax error", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dq4: \"a * (q4 + 1\"\n", 5, 22, "expected `)`"),
    ("unknown variable", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dq4: \"a * qq4\"\n", 5, 15, "unknown variable or parameter `qq4`"),
    ("unknown function", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dq4: \"a * sinh(q4)\"\n", 5, 15, "unknown function `sinh`"),
    ("wrong number of arguments", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dq4: \"min(a)\"\n", 5, 11, "takes 2 argument(s), found 1"),
    ("not finite at a pose", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dq4: \"a * ln(q4 - 2000)\"\n", 5, 11, "is NaN at line 3 of"),
    ("derivative not finite", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dq4: \"sqrt(a)\"\n", 5, 11, "has the derivative inf by `a` at line 3"),
    ("expression not text", "effects:\n  - name: e1\n    summary: s\n    params: {a: {unit: mm, prior: 1}}\n    dq4: [a]\n", 5, 10, "dq4: expected text"),
];

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

#[test]
fn every_malformed_effects_file_exits_2_naming_its_place() {
    let dir = tempfile::tempdir().expect("tempdir");
    let campaign = demo().display().to_string();
    let mut wrong = Vec::new();
    for (k, (what, text, line, column, words)) in CASES.iter().enumerate() {
        let path = dir.path().join(format!("case{k}.yaml"));
        std::fs::write(&path, text).expect("write");
        let file = path.display().to_string();
        let (code, err) = rpkm(&["diagnose", &campaign, "--effects-file", &file]);
        let place = format!("{file}:{line}:{column}: ");
        if code != Some(2)
            || !err.contains(&place)
            || !err.contains(words)
            || err.contains("panicked")
        {
            wrong.push(format!(
                "{what}: exit {code:?}, want {place}... {words}; got {err}"
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// The good file names each of its two parts in the messages of calibrate too: an effect
/// named by --effects that neither the library nor the file has, exit 2.
#[test]
fn an_unknown_effect_names_the_files_effects() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("good.yaml");
    std::fs::write(&path, GOOD).expect("write");
    let file = path.display().to_string();
    let campaign = demo().display().to_string();
    let (code, err) = rpkm(&[
        "calibrate",
        &campaign,
        "--effects-file",
        &file,
        "--effects",
        "cyclic_q1",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("unknown effect \"cyclic_q1\"") && err.contains("cyclic_q4"),
        "{err}"
    );
}

/// The foreign simulator's cyclic error of carrier 4's scale (2.5 µm, 60 mm pitch): offered
/// by the file, the effect is named, its amplitude √(a² + c²) is the truth's within 3σ, and
/// with it in the model the held-out error is at the floor. `rpkm calibrate` writes its
/// parameters (value, σ, unit) and expressions into the calibration JSON.
#[test]
fn the_foreign_cyclic_error_is_found_by_the_written_effect() {
    let Some(ds) = foreign_support::dataset("cyclic") else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let effects = dir.path().join("cyclic.yaml");
    std::fs::write(&effects, GOOD).expect("write");
    let truth = foreign_support::json(&ds.join("truth.json"));
    let amplitude = truth["hidden_effects"]["cyclic_q4"][0]
        .as_f64()
        .expect("amplitude");
    let diagnose = |extra: &[&str], out: &Path| {
        let o = Command::new(env!("CARGO_BIN_EXE_rpkm"))
            .arg("diagnose")
            .arg(ds.join("cal.csv"))
            .arg("--validate")
            .arg(ds.join("val.csv"))
            .arg("--effects-file")
            .arg(&effects)
            .arg("--json")
            .arg(out)
            .args(extra)
            .output()
            .expect("run rpkm");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        foreign_support::json(out)
    };
    let d = diagnose(&[], &dir.path().join("d1.json"));
    assert_eq!(d["missing_effect"], "cyclic_q4", "{}", d["candidates"]);
    assert_eq!(
        d["effects_file"]["effects"][0]["expressions"]["dq4"],
        "a * sin(2*pi*q4/60) + c * cos(2*pi*q4/60)"
    );
    let c = d["candidates"]
        .as_array()
        .expect("candidates")
        .iter()
        .find(|c| c["effect"] == "cyclic_q4")
        .expect("the file's effect among the candidates");
    let p = |k: usize, f: &str| c["params"][k][f].as_f64().expect("number");
    let (a, sa, cc, sc) = (p(0, "value"), p(0, "sigma"), p(1, "value"), p(1, "sigma"));
    let amp = a.hypot(cc);
    // first-order σ of the amplitude
    let sigma = ((a * sa).powi(2) + (cc * sc).powi(2)).sqrt() / amp;
    eprintln!(
        "cyclic_q4: a = {a:.5} ± {sa:.5}, c = {cc:.5} ± {sc:.5} mm, amplitude {amp:.5} ± {sigma:.5} (truth {amplitude}); \
         held-out {} -> {} um",
        c["val_rms_before_um"], c["val_rms_after_um"]
    );
    assert!(
        (amp - amplitude).abs() < 3.0 * sigma,
        "amplitude {amp} ± {sigma}, truth {amplitude}"
    );
    let d2 = diagnose(&["--effects", "cyclic_q4"], &dir.path().join("d2.json"));
    let after = d2["baseline"]["val_rms_um"].as_f64().expect("held-out");
    let floor = foreign_support::true_floor_um(&ds);
    eprintln!(
        "with cyclic_q4: verdict {}, held-out {after:.2} um, true floor {floor:.2} um",
        d2["verdict_kind"]
    );
    assert!(after <= 1.5 * floor, "held-out {after} um, floor {floor}");
    assert_eq!(
        d2["missing_effect"],
        serde_json::Value::Null,
        "{}",
        d2["candidates"]
    );
}

/// `rpkm calibrate --effects-file --effects cyclic_q4` writes the effect's parameters (value,
/// σ, unit) and the file's expressions into the calibration JSON.
#[test]
fn calibrate_writes_the_written_effects_parameters() {
    let Some(ds) = foreign_support::dataset("cyclic") else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let effects = dir.path().join("cyclic.yaml");
    std::fs::write(&effects, GOOD).expect("write");
    let cal_json = dir.path().join("cal.json");
    let o = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .arg("calibrate")
        .arg(ds.join("cal.csv"))
        .args(["--effects-file", &effects.display().to_string()])
        .args(["--effects", "cyclic_q4", "--json"])
        .arg(&cal_json)
        .output()
        .expect("run rpkm");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cal = foreign_support::json(&cal_json);
    let e = &cal["effects"][0];
    eprintln!("calibration JSON effects: {}", cal["effects"]);
    assert_eq!(
        (e["effect"].as_str(), e["name"].as_str(), e["unit"].as_str()),
        (Some("cyclic_q4"), Some("a"), Some("mm"))
    );
    let (a, sigma) = (
        e["value"].as_f64().expect("value"),
        e["sigma"].as_f64().expect("sigma"),
    );
    // the truth is a pure sine: a is its amplitude
    let truth = foreign_support::json(&ds.join("truth.json"));
    let amplitude = truth["hidden_effects"]["cyclic_q4"][0]
        .as_f64()
        .expect("amplitude");
    assert!(
        sigma > 0.0 && (a - amplitude).abs() < 3.0 * sigma,
        "a = {a} ± {sigma}, truth {amplitude}"
    );
    assert_eq!(
        cal["effects_file"]["effects"][0]["expressions"]["dq4"],
        "a * sin(2*pi*q4/60) + c * cos(2*pi*q4/60)"
    );
}

/// The tracker's drift after its zero written as data, as a user writes it.
const DRIFT: &str = "effects:
  - name: tracker_drift
    summary: the tracker's readings creep after its zero
    params: {vx: {unit: um/min, prior: 1}, vy: {unit: um/min, prior: 1}}
    instruments: [lt]
    dx: \"-vx * 1e-3 * t / 60\"
    dy: \"-vy * 1e-3 * t / 60\"
";

/// A twin whose tracker creeps 2 µm/min along y after each zero (2 µm tracker noise): the
/// written drift, offered, is named with vy within 3 σ of the twin's rate (vx, which the
/// tracker design's sweep cannot tell from the geometry, left out), and with it in the model
/// nothing is missing and the held-out error (each setup's zero removed) is at its floor.
#[test]
fn a_drifting_tracker_written_as_data_is_named_and_closes_at_the_floor() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (cal, effects) = (dir.path().join("cal.csv"), dir.path().join("drift.yaml"));
    std::fs::write(&effects, DRIFT).expect("write");
    let cal_s = cal.to_str().expect("utf-8");
    let (code, err) = rpkm(&[
        "simulate",
        "--campaign",
        "lt,kgm,self",
        "--drift",
        "lt=0,2",
        "--noise",
        "lt=0.002",
        "--seed",
        "3",
        "--out",
        cal_s,
        "--validation",
        "100",
    ]);
    assert_eq!(code, Some(0), "{err}");
    let val = dir.path().join("cal.val.csv");
    let diagnose = |extra: &[&str], name: &str| {
        let out = dir.path().join(name);
        let mut args = vec![
            "diagnose",
            cal_s,
            "--validate",
            val.to_str().expect("utf-8"),
        ];
        args.extend(["--effects-file", effects.to_str().expect("utf-8")]);
        args.extend(["--json", out.to_str().expect("utf-8")]);
        args.extend_from_slice(extra);
        let (code, err) = rpkm(&args);
        assert_eq!(code, Some(0), "{err}");
        foreign_support::json(&out)
    };
    let d = diagnose(&[], "d1.json");
    assert_eq!(
        d["missing_effects"],
        serde_json::json!(["tracker_drift"]),
        "{}",
        d["verdict"]
    );
    let (v, s, unit) = crate::diagnosis_support::candidate_param(&d, "tracker_drift", "vy");
    assert_eq!(unit, "um/min");
    assert!(
        (v - 2.0).abs() <= 3.0 * s,
        "vy = {v} ± {s} um/min, the twin's 2"
    );
    let d2 = diagnose(&["--effects", "tracker_drift"], "d2.json");
    assert_eq!(d2["verdict_kind"], "nothing_missing", "{}", d2["verdict"]);
    let h = &d2["held_out"];
    let (rms, floor) = (
        h["rms_relative_um"].as_f64().expect("rms"),
        h["floor_relative_um"].as_f64().expect("floor"),
    );
    assert!(h["consistent"] == true && rms < 1.2 * floor, "{h}");
}
