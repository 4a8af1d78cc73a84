//! `~/calibrate` (`rpkm_msgs/action/Calibrate`) on a running calibrator, driven by an
//! independent action client (Eclipse Cyclone DDS, tests/python/calibrate_action_peer.py,
//! types from msgs/action/Calibrate.action and ROS 2's action_msgs) on the demo campaign (the
//! embedded data, bags/demo/campaign.csv and its held-out campaign.val.csv):
//! 1. a goal with the held-out campaign: its result is the core's calibration of the same
//!    campaign with the node's options (the parameters within 1e-9, the LM iterations and
//!    noise rounds equal, the held-out RMS the core's TCP errors'); a feedback for every LM
//!    iteration (as many as the core makes over its rounds, the last round's as many as the
//!    calibration counts) and every noise round (the last one's levels the result's), then
//!    the diagnosis's; a verdict;
//! 2. a goal on a twin campaign of 20,000 tracker poses, cancelled by its id at its first
//!    iteration feedback: canceled, no parameters, and fewer iteration feedbacks than the
//!    core's calibration of that campaign makes. (The demo's whole calibration is 6 LM
//!    iterations in a few milliseconds, the time of a cancel's round trip: a goal cancelled
//!    "mid-way" needs iterations that take longer; these take about half a second.)
//! 3. a third goal (stated noise, no diagnosis) succeeds;
//! 4. the 20,000-pose goal again: at its diagnosis feedback `~/get_state` is answered while
//!    the goal runs (active), then the goal is cancelled: the diagnosis stops part-way
//!    ("stopped during the diagnosis"), canceled, no parameters; `~/get_state` then says
//!    active.
//!
//! Needs the venv; without it SKIPPED, under RPKM_REQUIRE_PYTHON=1 a failure.

use crate::node_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use std::cell::Cell;

use node_support::{python, rpkm, Proc, TempDir};
use rpkm_core::calib::{self, Flow, Options, Progress};
use rpkm_core::campaign::Campaign;
use rpkm_core::params::{index_of, unit, Params, Unit};
use serde_json::Value;

const DOMAIN: &str = "79";
/// Feedback phases (msgs/action/Calibrate.action).
const ITERATION: u64 = 1;
const NOISE_ROUND: u64 = 2;
const DIAGNOSIS: u64 = 3;

fn demo(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("bags/demo")
        .join(name)
}

/// The core's calibration of `campaign` with the node's default options (every parameter
/// under its tolerance, no outlier elimination, `noise`), and its LM iterations over all
/// its rounds.
pub(crate) fn core_calibration(
    campaign: &Path,
    noise: calib::Noise,
) -> (
    calib::Calibration,
    rpkm_core::variance::NoiseEstimate,
    usize,
) {
    let c = rpkm_nodes::input::read_campaign(campaign).expect("campaign");
    let opts = Options {
        outlier_sigma: None,
        ..Options::default()
    };
    let start = Params::nominal();
    let iterations = Cell::new(0);
    let count = |p: &Progress| {
        if let Progress::Iteration { .. } = p {
            iterations.set(iterations.get() + 1);
        }
        Flow::Continue
    };
    let (cal, est) = calib::calibrate(&calib::Request {
        noise,
        progress: Some(&count),
        ..calib::Request::new(&c, &start, &opts)
    })
    .expect("the core calibrates");
    (cal, est, iterations.get())
}

/// A twin campaign of 20,000 tracker poses in one setup (`grid`: not held out).
fn large_campaign(dir: &TempDir) -> PathBuf {
    let mut twin = rpkm_twin::Twin::new(rpkm_twin::TwinConfig {
        seed: 3,
        ..Default::default()
    })
    .expect("twin");
    let mut c = twin
        .campaign_by_names(&["validation"], 20_000)
        .expect("campaign");
    for p in &mut c.poses {
        p.setup = "grid".into();
    }
    let path = dir.path("grid.csv");
    std::fs::write(&path, c.to_csv()).expect("write campaign");
    path
}

/// The iteration feedbacks of each round, in order.
fn per_round(feedback: &[Value]) -> Vec<Vec<&Value>> {
    let mut rounds: Vec<Vec<&Value>> = Vec::new();
    for f in feedback.iter().filter(|f| f["phase"] == ITERATION) {
        let r = usize::try_from(f["round"].as_u64().expect("round")).expect("small");
        if rounds.len() < r {
            rounds.resize(r, Vec::new());
        }
        rounds[r - 1].push(f);
    }
    rounds
}

#[test]
fn a_cell_controller_calibrates_with_feedback_and_cancels_a_goal() {
    let Some(py) = python() else { return };
    let dir = TempDir::new("calact");
    let large = large_campaign(&dir);
    let _node = Proc(
        Command::new(rpkm())
            .args(["node", "calibrator", "--backend", "dds"])
            .env("ROS_DOMAIN_ID", DOMAIN)
            .spawn()
            .expect("start calibrator"),
    );
    let peer = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/calibrate_action_peer.py");
    let mut client = Command::new(&py);
    // The cell controller on the network interface, as one on another host: the results
    // (1.5 to 2.1 kB) then go as fragments (issue 50: they never arrived).
    crate::dds_large_samples::on_network_interface(&mut client);
    let out = client
        .arg(peer)
        .args([
            "--domain",
            DOMAIN,
            "--node",
            "/rpkm/calibrator",
            "--campaign",
        ])
        .arg(demo("campaign.csv"))
        .arg("--validation")
        .arg(demo("campaign.val.csv"))
        .arg("--cancel-campaign")
        .arg(&large)
        .args(["--timeout", "600"])
        .stderr(Stdio::inherit())
        .output()
        .expect("run the peer");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer: {text}");
    let report: Value = serde_json::from_str(text.trim()).expect("JSON report");
    let goals = report["goals"].as_array().expect("goals");
    check_calibrated(&goals[0], &text);
    let (_, _, whole) = core_calibration(&large, calib::Noise::ESTIMATE);
    check_cancelled(&goals[1], whole, &text);
    check_stated(&goals[2], &text);
    check_cancelled_in_the_diagnosis(&goals[3], whole, &text);
    assert_eq!(report["state"], 3, "the node is active after: {text}");
}

/// Goal 1 against the core.
fn check_calibrated(g: &Value, text: &str) {
    assert_eq!(
        (&g["accepted"], &g["status"]),
        (&Value::Bool(true), &Value::from(4)),
        "{text}"
    );
    let r = &g["result"];
    let (cal, noise, all) = core_calibration(&demo("campaign.csv"), calib::Noise::ESTIMATE);
    assert_eq!(r["iterations"], cal.iterations, "{text}");
    assert_eq!(r["noise_rounds"], noise.rounds, "{text}");
    let params = r["parameters"].as_object().expect("parameters");
    assert_eq!(params.len(), 29);
    for (name, v) in params {
        let i = index_of(name).expect("a parameter name");
        let scale = if unit(i) == Unit::Mm { 1e-3 } else { 1.0 };
        let v = v.as_f64().expect("a value");
        assert!(
            (v - cal.params[i] * scale).abs() < 1e-9,
            "{name}: {v} vs {}",
            cal.params[i]
        );
    }
    // the held-out RMS: the core's TCP errors of the validation campaign
    let val: Campaign = rpkm_nodes::input::read_campaign(&demo("campaign.val.csv")).expect("val");
    let errors: Vec<f64> = rpkm_core::obs::tcp_errors(&val, &cal.params, cal.model)
        .expect("tcp errors")
        .iter()
        .map(|e| e.value)
        .collect();
    let val_rms = r["val_rms"].as_f64().expect("a held-out RMS");
    assert!(
        (val_rms - calib::rms(&errors) * 1e-3).abs() < 1e-12,
        "{val_rms}"
    );
    assert!(
        ["nothing_missing", "missing_effect", "unexplained_structure"]
            .contains(&r["verdict"].as_str().expect("verdict")),
        "{text}"
    );
    check_feedback(g, (&cal, &noise, all), text);
}

/// Goal 1's feedback against the core's calibration `cal` of `noise.rounds` rounds and
/// `all` LM iterations.
fn check_feedback(
    g: &Value,
    (cal, noise, all): (
        &calib::Calibration,
        &rpkm_core::variance::NoiseEstimate,
        usize,
    ),
    text: &str,
) {
    let r = &g["result"];
    let feedback = g["feedback"].as_array().expect("feedback");
    let rounds = per_round(feedback);
    assert_eq!(rounds.len(), noise.rounds, "{text}");
    assert!(
        rounds.iter().all(|r| !r.is_empty()),
        "a round without feedback: {text}"
    );
    assert_eq!(rounds.last().map(Vec::len), Some(cal.iterations), "{text}");
    for round in &rounds {
        let numbers: Vec<u64> = round
            .iter()
            .map(|f| f["iteration"].as_u64().expect("it"))
            .collect();
        assert_eq!(
            numbers,
            (1..=numbers.len() as u64).collect::<Vec<_>>(),
            "{text}"
        );
    }
    let noise_rounds = feedback
        .iter()
        .filter(|f| f["phase"] == NOISE_ROUND)
        .count();
    assert_eq!(noise_rounds, noise.rounds, "{text}");
    let last_levels = g["noise_feedback"]
        .as_array()
        .and_then(|a| a.last())
        .expect("levels");
    for (group, levels) in r["noise"].as_object().expect("noise") {
        assert_eq!(last_levels[group], levels[1], "{group}: {text}");
    }
    assert_eq!(
        feedback.last().map(|f| &f["phase"]),
        Some(&Value::from(DIAGNOSIS))
    );
    assert_eq!(
        g["statuses"].as_array().and_then(|s| s.last()),
        Some(&Value::from(4))
    );
    let total: usize = rounds.iter().map(Vec::len).sum();
    assert_eq!(total, all, "one feedback per LM iteration: {text}");
    eprintln!(
        "goal 1: {total} iteration feedbacks over {} rounds ({:?} per round), the calibration \
         counts {} iterations in its last round; {} feedback messages in all; verdict {}",
        noise.rounds,
        rounds.iter().map(Vec::len).collect::<Vec<_>>(),
        cal.iterations,
        feedback.len(),
        r["verdict"]
    );
}

/// Goal 2: cancelled mid-way, before the `whole` calibration's iterations.
fn check_cancelled(g: &Value, whole: usize, text: &str) {
    assert_eq!(
        (&g["accepted"], &g["status"]),
        (&Value::Bool(true), &Value::from(5)),
        "{text}"
    );
    let cancel = &g["cancel"];
    assert_eq!(cancel["return_code"], 0, "{text}");
    assert_eq!(
        cancel["goals_canceling"],
        serde_json::json!([true]),
        "{text}"
    );
    let iterations = g["feedback"]
        .as_array()
        .expect("feedback")
        .iter()
        .filter(|f| f["phase"] == ITERATION)
        .count();
    assert!(
        iterations >= 1 && iterations < whole,
        "{iterations} of {whole}: {text}"
    );
    assert_eq!(g["result"]["parameters"], serde_json::json!({}), "{text}");
    assert!(
        g["result"]["message"]
            .as_str()
            .expect("message")
            .starts_with("cancelled"),
        "{text}"
    );
    let statuses = g["statuses"].as_array().expect("statuses");
    assert_eq!(
        &statuses[statuses.len() - 2..],
        [Value::from(3), Value::from(5)],
        "{text}"
    );
    eprintln!(
        "goal 2: cancelled after {iterations} of {whole} iteration feedbacks; {:.1} ms from \
         the cancel request to the result; {}",
        cancel["ms_to_result"].as_f64().expect("ms"),
        g["result"]["message"]
    );
}

/// Goal 4: the same campaign cancelled once its diagnosis began: the diagnosis stops (it
/// does not run to its end first), the goal is canceled with no parameters, after every
/// iteration of the calibration; the lifecycle's `~/get_state`, asked meanwhile, was answered.
fn check_cancelled_in_the_diagnosis(g: &Value, whole: usize, text: &str) {
    assert_eq!(
        (&g["accepted"], &g["status"]),
        (&Value::Bool(true), &Value::from(5)),
        "{text}"
    );
    let feedback = g["feedback"].as_array().expect("feedback");
    let iterations = feedback.iter().filter(|f| f["phase"] == ITERATION).count();
    assert!(iterations >= whole, "{iterations} of {whole}: {text}");
    assert_eq!(
        feedback.last().map(|f| &f["phase"]),
        Some(&Value::from(DIAGNOSIS)),
        "{text}"
    );
    assert_eq!(g["result"]["parameters"], serde_json::json!({}), "{text}");
    let message = g["result"]["message"].as_str().expect("message");
    assert!(
        message.starts_with("cancelled") && message.ends_with("stopped during the diagnosis"),
        "{message}: {text}"
    );
    // asked while the goal ran, `~/get_state` was answered (active) before the cancel
    let during = &g["cancel"]["state_during"];
    assert_eq!(during["id"], 3, "get_state during the goal: {text}");
    eprintln!(
        "goal 4: get_state answered in {:.1} ms while the goal ran; cancelled in the diagnosis, \
         {:.1} ms from the cancel request to the result; {message}",
        during["ms"].as_f64().expect("ms"),
        g["cancel"]["ms_to_result"].as_f64().expect("ms"),
    );
}

/// Goal 3: the stated noise, no diagnosis.
fn check_stated(g: &Value, text: &str) {
    assert_eq!(
        (&g["accepted"], &g["status"]),
        (&Value::Bool(true), &Value::from(4)),
        "{text}"
    );
    let (cal, _, _) = core_calibration(&demo("campaign.csv"), calib::Noise::Stated);
    let r = &g["result"];
    assert_eq!(r["noise_rounds"], 0, "{text}");
    assert_eq!(r["verdict"], "", "{text}");
    assert_eq!(r["iterations"], cal.iterations, "{text}");
    let rounds = per_round(g["feedback"].as_array().expect("feedback"));
    assert_eq!(rounds.len(), 1, "{text}");
    assert_eq!(rounds[0].len(), cal.iterations, "{text}");
}
