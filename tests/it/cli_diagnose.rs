//! `rpkm diagnose`, `rpkm calibrate --effects` and `rpkm demo` end to end: campaigns made by
//! `rpkm simulate` with a hidden effect, the diagnosis's JSON contract read back and checked
//! against the truth file the twin wrote.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::Command;

fn rpkm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rpkm"))
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rpkm-diag-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().expect("run rpkm");
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn json(path: &PathBuf) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("read json")).expect("json")
}

/// RMS (µm) of the held-out readings of `rpkm simulate`'s campaign `c` (its `.val.csv`)
/// against the same seed's readings without noise.
fn true_floor_um(dir: &std::path::Path, c: &std::path::Path) -> f64 {
    let clean = dir.join("clean.csv");
    run_ok(
        rpkm()
            .args([
                "simulate",
                "--campaign",
                "lt,kgm,self",
                "--effect",
                "thermal",
                "--seed",
                "9",
            ])
            .arg("--no-noise")
            .arg("--out")
            .arg(&clean),
    );
    let read = |p: PathBuf| {
        let text = std::fs::read_to_string(&p).expect("held-out campaign");
        rpkm_core::campaign::Campaign::parse(&text, "val").expect("parses")
    };
    rpkm_twin::reading_error_rms_um(
        &read(c.with_extension("val.csv")),
        &read(dir.join("clean.val.csv")),
    )
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn diagnose_names_the_hidden_effect_of_the_truth_file_and_calibrate_adds_it() {
    let dir = scratch("thermal");
    let (c, truth) = (dir.join("c.csv"), dir.join("truth.json"));
    run_ok(
        rpkm()
            .args([
                "simulate",
                "--campaign",
                "lt,kgm,self",
                "--effect",
                "thermal",
            ])
            .args([
                "--seed".as_ref(),
                "9".as_ref(),
                "--out".as_ref(),
                c.as_os_str(),
                "--truth".as_ref(),
                truth.as_os_str(),
            ]),
    );
    let hidden = json(&truth)["effects"][0]["effect"]
        .as_str()
        .expect("effect in truth")
        .to_owned();
    let (d, report) = (dir.join("d.json"), dir.join("report"));
    let stdout = run_ok(
        rpkm()
            .arg("diagnose")
            .arg(&c)
            .arg("--validate")
            .arg(dir.join("c.val.csv"))
            .arg("--json")
            .arg(&d)
            .arg("--report")
            .arg(&report),
    );
    assert!(
        stdout.contains("Verdict (missing_effect): missing effect: thermal"),
        "{stdout}"
    );
    let d = json(&d);
    assert_eq!(d["missing_effect"].as_str(), Some(hidden.as_str()));
    let b = &d["baseline"];
    // the floor of these held-out readings: the twin's truth, the same poses measured
    // without noise (the reported floor is the expected one, which counts the error of the
    // held-out setup's zero reading as one draw of many)
    let floor = true_floor_um(&dir, &c);
    let reported = b["noise_floor_um"].as_f64().expect("noise_floor_um");
    assert!(reported > 0.0);
    assert!(b["cal_rms_um"].as_f64().expect("cal_rms_um") > 0.0);
    assert!(b["val_rms_um"].as_f64().expect("val_rms_um") > 1.3 * floor);
    let first = &d["candidates"][0];
    assert_eq!(first["effect"].as_str(), Some("thermal"));
    assert_eq!(first["significant"].as_bool(), Some(true));
    assert!(first["explained_fraction"].as_f64().expect("fraction") > 0.9);
    assert!(first["val_rms_after_um"].as_f64().expect("after") < 1.5 * floor);
    assert!(first["val_rms_before_um"].as_f64().is_some());
    // one self-contained page: the charts inline, the named effect's "after" beside "before"
    let page = std::fs::read_to_string(report.join("report.html")).expect("report page");
    assert!(page.matches("<figure class=\"plot\"><svg").count() >= 10);
    assert!(!page.contains(".svg\"") && page.contains("with thermal"));
    let r = json(&report.join("report.json"));
    assert_eq!(r["effects_after"], serde_json::json!(["thermal"]));

    // adding it with calibrate --effects: the table falls to the floor
    let cj = dir.join("cal.json");
    let chart = dir.join("stages.svg");
    run_ok(
        rpkm()
            .arg("calibrate")
            .arg(&c)
            .args(["--model", "24", "--effects", "thermal", "--validate"])
            .arg(dir.join("c.val.csv"))
            .arg("--json")
            .arg(&cj)
            .arg("--chart")
            .arg(&chart)
            .arg("--report")
            .arg(dir.join("cal-report")),
    );
    let stages = json(&cj)["effect_stages"].clone();
    let v0 = stages[0]["val_rms_um"].as_f64().expect("stage 0");
    let v1 = stages[1]["val_rms_um"].as_f64().expect("stage 1");
    assert!(v1 < 1.5 * floor && v0 > 1.3 * floor, "{v0} -> {v1}");
    let alpha = stages[1]["effect_params"][0]["value"]
        .as_f64()
        .expect("alpha");
    let truth_alpha = json(&truth)["alpha_per_k"].as_f64().expect("alpha truth") * 1e6;
    assert!(
        (alpha - truth_alpha).abs() < 0.05 * truth_alpha,
        "{alpha} vs {truth_alpha}"
    );
    // the calibration itself is the model's with the effect: its held-out error at the
    // floor, its own α where the table's last stage has it
    let cal = json(&cj);
    let after = cal["val_rms_after_um"].as_f64().expect("val_rms_after_um");
    assert!(after < 1.5 * floor, "calibrated with thermal: {after} um");
    let alpha_cal = cal["effects"][0]["value"].as_f64().expect("effects");
    assert!(
        (alpha_cal - truth_alpha).abs() < 0.05 * truth_alpha,
        "{alpha_cal} vs {truth_alpha}"
    );
    assert!(chart.exists());
    // its report: the table's stages, the model with thermal as "after"
    let r = json(&dir.join("cal-report/report.json"));
    assert_eq!(r["effects_after"], serde_json::json!(["thermal"]));
    assert_eq!(r["stages"][1]["val_rms_um"].as_f64(), Some(v1));
}

#[test]
fn unknown_effect_is_bad_input() {
    let out = rpkm()
        .args([
            "diagnose",
            "bags/demo/campaign.csv",
            "--effects",
            "thermal,backlash",
        ])
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--effects") && err.contains("\"backlash\""),
        "{err}"
    );
}

#[test]
fn demo_names_the_effect_hidden_in_its_embedded_data() {
    let dir = scratch("demo");
    let stdout = run_ok(rpkm().arg("demo").arg("--out").arg(&dir));
    let truth = json(&PathBuf::from("bags/demo/truth.json"));
    let hidden = truth["effects"][0]["effect"].as_str().expect("effect");
    assert!(
        stdout.contains(&format!(
            "Verdict (missing_effect): missing effect: {hidden}"
        )),
        "{stdout}"
    );
    assert!(
        stdout.contains("verdict now: nothing is missing"),
        "{stdout}"
    );
    assert!(dir.join("report.html").exists());
}

/// One machine of `rpkm bench discovery` (seed 1 unless given): its loop's outcome, as the
/// bench's JSON.
fn bench_machine(i: usize) -> serde_json::Value {
    bench_machine_of(1, i)
}

fn bench_machine_of(seed: u64, i: usize) -> serde_json::Value {
    let out = run_ok(
        rpkm()
            .args(["bench", "discovery", "--seed"])
            .arg(seed.to_string())
            .arg("--only")
            .arg(i.to_string()),
    );
    let at = out
        .find("\n{")
        .expect("the outcome's JSON after the loop's lines");
    serde_json::from_str(&out[at..]).expect("outcome JSON")
}

/// Two machines with two library effects hidden, of the kinds whose loop once named an
/// effect that raised the held-out error (thermal with encoder_scale: the model with
/// encoder_scale alone predicted 35.5 µm in one diagnosis and 1522 µm in the next, weighted
/// by another noise estimate; preload with thermal: thermal's supported part predicted
/// better, its whole family worse): 149 and 113 of the series of seed 1. Each step of the
/// loop now predicts at least as well as the last, within twice the standard error of the
/// paired held-out errors, and the loop names exactly what the twin hid, the two together,
/// and ends at its floor.
#[test]
fn no_step_of_the_loop_raises_the_held_out_error() {
    for (machine, hidden) in [
        (149, ["encoder_scale", "thermal"]),
        (113, ["preload_elastic", "thermal"]),
    ] {
        let o = bench_machine(machine);
        assert_eq!(named_of(&o), hidden, "machine {machine}: {o}");
        assert_eq!(
            o["final_verdict"], "nothing_missing",
            "machine {machine}: {o}"
        );
        let rise = o["largest_rise_se"].as_f64().expect("largest_rise_se");
        assert!(
            rise <= 2.0,
            "machine {machine}: a step rose by {rise:.2} SE: {o}"
        );
        let path: Vec<f64> = o["held_out_path_um"]
            .as_array()
            .expect("path")
            .iter()
            .map(|v| v.as_f64().expect("µm"))
            .collect();
        // one diagnosis per named effect, or one for a pair named together, then the last
        assert!((2..=3).contains(&path.len()), "machine {machine}: {o}");
        // each step lowers the error; where it ends is the floor (below), not a fraction
        // of the start (a noisy tracker's floor may be half the start or more)
        assert!(
            path.windows(2).all(|w| w[1] < w[0]),
            "machine {machine}: {o}"
        );
        let over_floor = o["held_out_over_floor"].as_f64().expect("ratio");
        assert!((0.9..1.1).contains(&over_floor), "machine {machine}: {o}");
    }
}

/// The names a bench machine's loop named, sorted.
fn named_of(o: &serde_json::Value) -> Vec<String> {
    let mut named: Vec<String> = o["named"]
        .as_array()
        .expect("named")
        .iter()
        .map(|v| v.as_str().expect("name").to_owned())
        .collect();
    named.sort_unstable();
    named
}

/// Two machines of the benchmark whose models were once chosen wrong as a whole. Machine 124
/// of seed 1 hides a rod of another stiffness than the others, all drives active: the preload's
/// pair with `encoder_scale` was named, the guides' scale difference absorbing part of the
/// rod's force-following residual. Then `preload_elastic` was named alone and the loop said
/// structure was left; with a rod of its own compliance (`preload_elastic:rodN`) nothing is
/// missing at the floor.
/// Machine 171 of seed 2 hides thermal expansion of the rods and scales (frame 0) with the
/// preload: the preload with thermal's rods and scales was never tried together, and the
/// pair against thermal alone was a tie on the held-out tracker where the setups left out
/// decide; now the pair is named and nothing is missing. Machine 0 of seed 2 is another soft
/// rod: the guides' scale difference came out 2.0 ± 1.0 and 0.4 ± 1.0 ppm beside the preload,
/// below a twentieth of a plausible one (50 ppm), and the pair was named; what a larger model
/// adds must now matter as a candidate's parameters must.
#[test]
fn the_model_is_chosen_whole_where_parts_absorb_each_other() {
    for (seed, machine) in [(1, 124), (2, 0)] {
        let soft = bench_machine_of(seed, machine);
        assert_eq!(named_of(&soft), ["preload_elastic"], "{soft}");
        assert_eq!(soft["final_verdict"], "nothing_missing", "{soft}");
        let over_floor = soft["held_out_over_floor"].as_f64().expect("ratio");
        assert!((0.9..1.1).contains(&over_floor), "{soft}");
    }
    let pair = bench_machine_of(2, 171);
    assert_eq!(named_of(&pair), ["preload_elastic", "thermal"], "{pair}");
    assert_eq!(pair["final_verdict"], "nothing_missing", "{pair}");
    let over_floor = pair["held_out_over_floor"].as_f64().expect("ratio");
    assert!((0.9..1.1).contains(&over_floor), "{pair}");
}

/// Machine 120 of seed 2 hides a parallel-holder 2.4 mm off and an 85 ppm scale difference
/// between the guides. The geometry alone misses them by 0.4 mm on the tracker, so the noise
/// estimated under it is 79x the tracker's stated noise and 100x the grid encoder's; judged
/// against that, a rod-5 error of its prior size (0.1 mm) moved the fit by less than one
/// standard deviation, the parallel-holder was held as unobservable, and nothing was named
/// (`unexplained_structure`, the held-out error 2.8x its floor). An effect's size is now
/// judged against what the instruments resolve: both are named, and the loop ends at the floor.
#[test]
fn an_effect_stays_observable_under_the_noise_its_own_misfit_inflates() {
    let o = bench_machine_of(2, 120);
    assert_eq!(named_of(&o), ["encoder_scale", "parallelogram"], "{o}");
    assert_eq!(o["final_verdict"], "nothing_missing", "{o}");
    let over_floor = o["held_out_over_floor"].as_f64().expect("ratio");
    assert!((0.9..1.1).contains(&over_floor), "{o}");
}

/// A tracker that creeps 1.8 µm/min along its beam after each zero (machine 119 of the
/// benchmark's seed 4, its drift offered written as data): the held-out tracker's along-beam
/// errors hold the ramp (the held-out residual follows `t`), its across-beam ones (tens of
/// µm) drown it in mm (the RMS moves 22.88 -> 22.80 µm). Judged in each error's own noise,
/// with the held-out errors regressed on the change, the drift is named and the loop ends
/// `nothing_missing`. `--write` leaves the machine's files: `rpkm diagnose` on them names
/// the drift with vy within 3 σ of the twin's rate.
#[test]
fn a_drift_along_the_beam_is_named_in_its_own_noise() {
    let dir = scratch("drift-beam");
    let out = run_ok(
        rpkm()
            .args([
                "bench",
                "discovery",
                "--seed",
                "4",
                "--only",
                "119",
                "--write",
            ])
            .arg(&dir),
    );
    let at = out
        .find("\n{")
        .expect("the outcome's JSON after the loop's lines");
    let o: serde_json::Value = serde_json::from_str(&out[at..]).expect("outcome JSON");
    assert_eq!(named_of(&o), ["tracker_drift"], "{o}");
    assert_eq!(o["final_verdict"], "nothing_missing", "{o}");
    // the twin's rate, mm/s along x and y, as the machine's file gives it
    let machine = std::fs::read_to_string(dir.join("machine.txt")).expect("machine.txt");
    let after = &machine[machine.find("rate_per_s").expect("the drift's rate")..];
    let rate: Vec<f64> = after
        .split(|c: char| !(c.is_ascii_digit() || ".-e".contains(c)))
        .filter_map(|w| w.parse().ok())
        .take(2)
        .collect();
    let truth_vy = rate[1] * 1e3 * 60.0;
    let report = dir.join("d.json");
    run_ok(
        rpkm()
            .arg("diagnose")
            .arg(dir.join("cal.csv"))
            .arg("--validate")
            .arg(dir.join("val.csv"))
            .arg("--effects-file")
            .arg(dir.join("effects.yaml"))
            .arg("--json")
            .arg(&report),
    );
    let d = json(&report);
    assert_eq!(
        d["missing_effects"],
        serde_json::json!(["tracker_drift"]),
        "{}",
        d["verdict"]
    );
    let (v, s, unit) = crate::diagnosis_support::candidate_param(&d, "tracker_drift", "vy");
    assert_eq!(unit, "um/min");
    assert!(
        (v - truth_vy).abs() <= 3.0 * s,
        "vy = {v} ± {s} um/min, the twin's {truth_vy}"
    );
    // its held-out support is the regression's, far beyond what the fall alone showed
    let drift = crate::diagnosis_support::candidate(&d, "tracker_drift");
    let support = drift["prediction"]["support_p"]
        .as_f64()
        .expect("support_p");
    assert!(support < 1e-4, "{}", drift["prediction"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// The preload's rod forces balance through the rods' directions, so its stretch moves with
/// the geometry the fit moves: 0.3 % of a parallelogram rod's force per 0.1 mm. The fit held
/// it where it was balanced and bound it again between noise rounds without converging: on
/// this twin the diagnosis's model with `preload_elastic` stopped at chi2/dof 1.11 where every
/// candidate, fitted with one binding more, reached 0.70, and the verdict was
/// `unexplained_structure` ("the self q2 residual follows x", r = -0.78). With the stretch's
/// slope in the Jacobian nothing is missing and the compliance is the twin's (1, its rods at
/// the default stiffness). Two machines of the benchmark whose preload read the pose another
/// effect moves (seed 7's 122, seed 2's 90 with a parallel-holder) end the same way.
#[test]
fn a_preloaded_machine_is_fitted_to_its_minimum() {
    let dir = scratch("preload-minimum");
    let cal = dir.join("c.csv");
    simulate_preloaded(&cal, &[]);
    let mut args: Vec<OsString> = vec!["diagnose".into(), (&cal).into()];
    args.extend(["--validate".into(), cal.with_extension("val.csv").into()]);
    args.extend(["--effects", "preload_elastic"].map(OsString::from));
    let d = rpkm_json(&dir.join("d.json"), &args);
    assert_eq!(d["verdict_kind"], "nothing_missing", "{}", d["verdict"]);
    let candidates = d["candidates"].as_array().expect("candidates");
    assert!(
        candidates.iter().all(|c| c["significant"] == false),
        "{}",
        d["verdict"]
    );
    let (v, s) = crate::diagnosis_support::effect_value(&d["effect_values"], "compliance");
    assert!((v - 1.0).abs() <= 3.0 * s, "compliance {v} ± {s}");
    // its rods are alike: none is given a compliance of its own
    assert_eq!(d["model_effects"], serde_json::json!(["preload_elastic"]));
    for (seed, machine, hidden) in [
        (7, 122, vec!["preload_elastic"]),
        (2, 90, vec!["parallelogram", "preload_elastic"]),
    ] {
        let o = bench_machine_of(seed, machine);
        assert_eq!(named_of(&o), hidden, "seed {seed} machine {machine}: {o}");
        assert_eq!(
            o["final_verdict"], "nothing_missing",
            "seed {seed} machine {machine}: {o}"
        );
    }
}

/// A rod 30 % stiffer than the others, all drives active: it takes another share of the
/// preload, and a compliance for all rods leaves its misfit. The guides' scale difference
/// beside the preload absorbed part of it and was named (13 such machines of the benchmark's
/// seven seeds). The preload's refinement with a compliance of its own for rod 3 is named
/// instead, the next diagnosis settles `preload_elastic` to it, and both compliances are the
/// twin's: the others' 1, rod 3's the default stiffness over its own.
#[test]
fn a_rod_of_another_stiffness_is_given_its_own_compliance() {
    let dir = scratch("stiff-rod");
    let (cal, truth) = (dir.join("c.csv"), dir.join("t.json"));
    simulate_preloaded(
        &cal,
        &[
            "--rod-stiffness".into(),
            "3=1.3".into(),
            "--truth".into(),
            (&truth).into(),
        ],
    );
    let rods = json(&truth)["stiffness"]["rod"].clone();
    let k = |r: usize| rods[r].as_f64().expect("stiffness");
    let val = cal.with_extension("val.csv");
    let diagnose = |effects: &str, out: &str| {
        let mut args: Vec<OsString> = vec!["diagnose".into(), (&cal).into()];
        args.extend(["--validate".into(), (&val).into()]);
        if !effects.is_empty() {
            args.extend(["--effects".into(), effects.into()]);
        }
        rpkm_json(&dir.join(out), &args)
    };
    let first = diagnose("", "d0.json");
    assert_eq!(
        first["missing_effects"],
        serde_json::json!(["preload_elastic:rod3"]),
        "{}",
        first["verdict"]
    );
    assert_eq!(first["missing_effect"], "preload_elastic");
    let d = diagnose("preload_elastic", "d1.json");
    assert_eq!(
        d["model_effects"],
        serde_json::json!(["preload_elastic:rod3"])
    );
    assert_eq!(d["verdict_kind"], "nothing_missing", "{}", d["verdict"]);
    let values = &d["effect_values"];
    let (common, s) = crate::diagnosis_support::effect_value(values, "compliance");
    // rods 1, 2, 4 and 5 at the model's default stiffness, rod 3 at its own
    assert!((common - 1.0).abs() <= 3.0 * s, "compliance {common} ± {s}");
    let want = k(0) / k(2);
    let rod3 = |values: &serde_json::Value| {
        let (own, s) = crate::diagnosis_support::effect_value(values, "compliance_rod3");
        assert!(
            (own - want).abs() <= 3.0 * s,
            "rod 3: {own} ± {s}, twin {want}"
        );
    };
    rod3(values);
    // `rpkm calibrate` fits the effects as given and says what the data settle them to;
    // given the settled refinement, it finds the twin's compliance
    let calibrate = |effects: &str, out: &str| {
        let mut args: Vec<OsString> = vec!["calibrate".into(), (&cal).into()];
        args.extend(["--model", "29", "--effects", effects].map(OsString::from));
        args.extend(["--validate".into(), (&val).into()]);
        rpkm_json(&dir.join(out), &args)
    };
    let plain = calibrate("preload_elastic", "c0.json");
    assert_eq!(
        plain["effect_stages_settled_as"],
        serde_json::json!(["preload_elastic:rod3"])
    );
    let settled = calibrate("preload_elastic:rod3", "c1.json");
    assert!(settled.get("effect_stages_settled_as").is_none());
    rod3(&settled["effects"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// A tracker, a grid encoder and self-calibration of a twin with all drives active, its
/// controller's parameter error 0.765 (the preload's scale; 0.3 by default), with `extra`
/// options (its held-out poses beside `cal`).
fn simulate_preloaded(cal: &std::path::Path, extra: &[OsString]) {
    let mut cmd = rpkm();
    cmd.args(["simulate", "--campaign", "lt,kgm,self", "--effect"])
        .args(["preload_elastic=0.765", "--seed", "4", "--out"])
        .arg(cal)
        .args(extra);
    run_ok(&mut cmd);
}

/// `rpkm ARGS --json REPORT`, its JSON read back.
fn rpkm_json(report: &std::path::Path, args: &[OsString]) -> serde_json::Value {
    run_ok(rpkm().args(args).arg("--json").arg(report));
    json(&report.to_path_buf())
}
