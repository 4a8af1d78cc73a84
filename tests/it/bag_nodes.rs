//! Reference bags replayed through the launched node set (`rpkm launch`, real processes over
//! iceoryx2, `rpkm replay`), the outputs checked against the core's direct computation and the
//! twin's truth file, not against an earlier recording:
//! - `bags/preload_fault` through tcp_estimator and preload_monitor, configured with the true
//!   parameters of `preload_fault.truth.json`: one PreloadStatus and one TcpEstimate per
//!   sample, each equal to `rpkm_core::elastic::fegm` at the sample's encoders; WARN and ERROR
//!   raised at the samples the core's deviations give;
//! - `bags/stream_8khz` (at 1 kHz) through tcp_estimator with the true parameters: one
//!   TcpEstimate per sample, equal to the core's rigid fgm of the holding drives (q2, q3 are
//!   followers: nothing is preloaded) and on the programmed circle of the truth file; the
//!   recorder of the launch (`executable: rpkm record`) closes a bag holding the same;
//! - `bags/calibration` through the calibrator: the Parameters it publishes are those of
//!   `rpkm calibrate` on the equivalent CSV (`bags/demo/campaign.csv`), parameter by parameter;
//! - `bags/calibration` and `bags/calibration_val` through the calibrator: its Diagnosis is
//!   that of `rpkm diagnose` on the equivalent CSVs and names the effect the twin hid.

use crate::bag_support;
use crate::node_support;

use std::collections::HashMap;
use std::time::{Duration, Instant};

use bag_support::{decode_all, reference_bag, repo_root, rpkm, run_ok, scratch, Watched};
use node_support::{unique, Launch};
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE, NOMINAL_DRIVE_FORCE_N};
use rpkm_core::params::{self, Params, NAMES};
use rpkm_msgs::{
    ActuatorState, Diagnosis, Parameters, PreloadStatus, TcpEstimate, TcpMeasurement, Time,
};
use rpkm_transport::{topic, Transport, TransportConfig};
use serde_json::Value;

const WARN: f64 = 30.0;
const ERROR: f64 = 80.0;
const DEBOUNCE: usize = 3;
/// Replay speed: 500 samples/s, what a loaded two-core machine keeps up with.
const RATE: &str = "0.5";

fn truth_params(truth: &Value) -> Params {
    let mut p = Params::nominal();
    for (name, v) in truth["params"].as_object().expect("params") {
        p[params::index_of(name).expect("known name")] = v.as_f64().expect("number");
    }
    p
}

/// First sample at which the largest |deviation| has held `threshold` for DEBOUNCE samples.
fn first_held(dev: &[[f64; 4]], threshold: f64) -> Option<usize> {
    let mut run = 0;
    for (k, d) in dev.iter().enumerate() {
        let worst = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        run = if worst >= threshold { run + 1 } else { 0 };
        if run >= DEBOUNCE {
            return Some(k);
        }
    }
    None
}

#[test]
fn preload_fault_bag_through_the_monitor_matches_the_core() {
    let dir = scratch("nodes-preload");
    let truth: Value = serde_json::from_str(
        &std::fs::read_to_string(reference_bag("preload_fault.truth.json")).expect("truth"),
    )
    .expect("JSON");
    let geometry = dir.join("true_params.json");
    let p = geometry_file(&truth, &geometry);
    let k: Stiffness = serde_json::from_value(truth["stiffness"].clone()).expect("stiffness");
    assert_eq!(
        k,
        Stiffness::default(),
        "the nodes assume the twin's stiffness"
    );
    std::fs::write(
        dir.join("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    geometry_file: {}\n    diagnostics_period_s: 0.2\n\
             tcp_estimator:\n  ros__parameters:\n    busy_poll_ms: 0.0\n\
             preload_monitor:\n  ros__parameters:\n    warn_percent: {WARN}\n    \
             error_percent: {ERROR}\n    debounce_samples: {DEBOUNCE}\n    status_every: 1\n    \
             busy_poll_ms: 0.0\n",
            geometry.display()
        ),
    )
    .expect("params.yaml");
    let launch_file = dir.join("bag.launch.yaml");
    std::fs::write(
        &launch_file,
        "launch:\n  - node: {pkg: rpkm, exec: tcp_estimator, param: [{from: params.yaml}]}\n  \
         - node: {pkg: rpkm, exec: preload_monitor, param: [{from: params.yaml}]}\n",
    )
    .expect("launch file");

    // Expected, per sample, from the core directly.
    let states: Vec<ActuatorState> =
        decode_all(&reference_bag("preload_fault"), "/rpkm/actuator_state");
    let n = states.len();
    let pct = |f: f64| f / NOMINAL_DRIVE_FORCE_N * 100.0;
    let expected: Vec<_> = states
        .iter()
        .map(|s| {
            let q = s.position.map(|v| v * 1e3);
            let eq = fegm(&p, &k, q, ALL_ACTIVE).expect("core fegm");
            let dev = [0, 1, 2, 3].map(|i| pct(s.force[i]) - pct(eq.drive_force[i]));
            (eq, dev)
        })
        .collect();
    let index: HashMap<Time, usize> = states
        .iter()
        .enumerate()
        .map(|(i, s)| (s.stamp, i))
        .collect();

    let prefix = unique("bagpm");
    let observer = Transport::new(&TransportConfig::new(unique("bagobs")).ipc_prefix(&prefix))
        .expect("transport");
    let statuses = observer.subscriber(&topic::PRELOAD_STATUS).expect("sub");
    let estimates = observer.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let diagnostics = observer.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let mut launched = Launch::start(&launch_file, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    // The nodes are subscribed once they report on /diagnostics.
    let mut reporting = std::collections::BTreeSet::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while reporting.len() < 2 {
        assert!(
            Instant::now() < deadline,
            "nodes not reporting: {reporting:?}"
        );
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            reporting.extend(d.status.into_iter().map(|s| s.name));
        }
        reporting.retain(|n| n == "rpkm/preload_monitor" || n == "rpkm/tcp_estimator");
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut replay = Watched::spawn(
        rpkm()
            .arg("replay")
            .arg(reference_bag("preload_fault"))
            .args(["--rate", RATE, "--ipc-prefix", &prefix]),
    );
    let mut got_status: Vec<Option<PreloadStatus>> = vec![None; n];
    let mut got_estimate: Vec<Option<TcpEstimate>> = vec![None; n];
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let mut idle = true;
        while let Some(s) = statuses.try_recv().expect("recv") {
            idle = false;
            let i = *index.get(&s.stamp).expect("a stamp of the bag");
            got_status[i] = Some(s);
        }
        while let Some(e) = estimates.try_recv().expect("recv") {
            idle = false;
            let i = *index.get(&e.stamp).expect("a stamp of the bag");
            got_estimate[i] = Some(e);
        }
        while diagnostics.try_recv().expect("recv").is_some() {}
        let done = got_status[n - 1].is_some() && got_estimate[n - 1].is_some();
        if done || Instant::now() > deadline {
            break;
        }
        if idle {
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    let status = replay.wait(Duration::from_secs(60));
    assert!(status.success(), "replay: {}", replay.seen.join("\n"));
    launched.stop();

    let lost_s = got_status.iter().filter(|s| s.is_none()).count();
    let lost_e = got_estimate.iter().filter(|s| s.is_none()).count();
    assert_eq!(
        (lost_s, lost_e),
        (0, 0),
        "one PreloadStatus and one TcpEstimate per sample"
    );
    for (i, ((eq, dev), (s, e))) in expected
        .iter()
        .zip(got_status.iter().zip(&got_estimate))
        .enumerate()
    {
        let (Some(s), Some(e)) = (s, e) else { continue };
        for (d, (got, want)) in s.deviation.iter().zip(dev).enumerate() {
            assert!(
                (got - want).abs() < 1e-6,
                "sample {i}, q{}: deviation {got} vs core {want}",
                d + 1
            );
        }
        assert!(
            (e.x - eq.x / 1e3).abs() < 1e-9 && (e.y - eq.y / 1e3).abs() < 1e-9,
            "sample {i}: estimate ({}, {}) m vs core ({}, {}) mm",
            e.x,
            e.y,
            eq.x,
            eq.y
        );
        // The twin held (0, 1700) mm: the estimate is there but for the fault and the
        // controller's error (below a millimetre).
        assert!(
            e.x.abs() < 1e-3 && (e.y - 1.7).abs() < 1e-3,
            "sample {i}: ({}, {})",
            e.x,
            e.y
        );
    }
    let devs: Vec<[f64; 4]> = expected.iter().map(|(_, d)| *d).collect();
    let k_warn = first_held(&devs, WARN).expect("the fault crosses WARN");
    let k_error = first_held(&devs, ERROR).expect("the fault crosses ERROR");
    let first = |level: u8| {
        got_status
            .iter()
            .position(|s| s.is_some_and(|s| s.level == level))
            .expect("level reached")
    };
    assert_eq!(
        first(PreloadStatus::WARN),
        k_warn,
        "WARN at the core's sample"
    );
    assert_eq!(
        first(PreloadStatus::ERROR),
        k_error,
        "ERROR at the core's sample"
    );
    assert!(
        k_warn > 0 && k_error < n - 1,
        "the bag starts OK and ends in ERROR"
    );
}

/// The calibration bag in recorded order (nodes/src/node/calibrator/node.rs): each poll drains the states,
/// then the measurements; the calibrator pairs them by stamp whatever order they arrive in
/// (it keeps an unpaired measurement until its state has come).
#[test]
fn calibration_bag_through_the_calibrator_gives_rpkm_calibrate_s_parameters() {
    check_calibrator(false);
}

/// The same with every state published before the measurements (two replays of the bag,
/// `--topics`): the calibrator's state buffer pairs them all, whatever the timing.
#[test]
fn calibration_bag_states_first_through_the_calibrator_gives_rpkm_calibrate_s_parameters() {
    check_calibrator(true);
}

fn check_calibrator(states_first: bool) {
    let dir = scratch(if states_first {
        "nodes-calibrator-split"
    } else {
        "nodes-calibrator"
    });
    // The command-line calibration of the equivalent CSV, with its defaults (model 29,
    // automatic selection up to condition 100, 3-sigma outliers): the node's defaults.
    let json = dir.join("cli.json");
    run_ok(
        rpkm()
            .arg("calibrate")
            .arg(repo_root().join("bags/demo/campaign.csv"))
            .arg("--json")
            .arg(&json),
    );
    let cli: Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("JSON");
    // 1059 s of campaign in about a second.
    let passes: &[(&str, Option<&str>)] = if states_first {
        &[
            ("calibration", Some("/rpkm/actuator_state")),
            (
                "calibration",
                Some("/rpkm/campaign_info,/rpkm/tcp_measurement"),
            ),
        ]
    } else {
        &[("calibration", None)]
    };
    let out = run_calibrator(&dir, "", passes);
    let (got, report) = (out.parameters, out.report);

    assert_eq!(u64::from(got.model), cli["model"].as_u64().expect("model"));
    // Measurements (one per pose of the campaign: its data lines), not the fit's rows.
    let csv = std::fs::read_to_string(repo_root().join("bags/demo/campaign.csv")).expect("csv");
    let poses = csv.lines().filter(|l| !l.starts_with('#')).count() - 1;
    assert_eq!(poses, 194);
    assert_eq!(
        got.measurement_count as usize, poses,
        "every measurement of the campaign; calibrator: {report}"
    );
    let want = cli["parameters"].as_object().expect("parameters");
    assert_eq!(got.names.len(), want.len());
    for (name, value) in got.names.iter().zip(&got.values) {
        let i = params::index_of(name).expect("known name");
        let w = want[name].as_f64().expect("number");
        // Lengths: the node publishes m, the CLI writes mm; angles rad on both.
        let got_native = match params::unit(i) {
            params::Unit::Mm => value * 1e3,
            params::Unit::Rad => *value,
        };
        // the bag carries SI values: its rounding moves the noise estimation's last round by
        // a nanometre, a thousandth of the parameters' σ
        let tol = match params::unit(i) {
            params::Unit::Mm => 1e-5,
            params::Unit::Rad => 1e-8,
        };
        assert!(
            (got_native - w).abs() < tol,
            "{name}: calibrator {got_native} vs rpkm calibrate {w}"
        );
    }
}

/// The calibration bag and its held-out poses (`bags/calibration_val`, setup `val`) through
/// the calibrator with the 24-parameter model: the Diagnosis it publishes is the one of
/// `rpkm diagnose` on the equivalent CSVs (`rpkm bag campaign` of both bags), candidate by
/// candidate, and it names the effect the twin hid (the truth file's parallelogram).
#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn calibration_bags_through_the_calibrator_give_rpkm_diagnose_s_diagnosis() {
    let dir = scratch("nodes-calibrator-diagnosis");
    let csv = |bag: &str| {
        let path = dir.join(format!("{bag}.csv"));
        run_ok(
            rpkm()
                .args(["bag", "campaign"])
                .arg(reference_bag(bag))
                .arg("--out")
                .arg(&path),
        );
        path
    };
    let (cal_csv, val_csv) = (csv("calibration"), csv("calibration_val"));
    let json = dir.join("diagnose.json");
    run_ok(
        rpkm()
            .arg("diagnose")
            .arg(&cal_csv)
            .arg("--validate")
            .arg(&val_csv)
            .args(["--model", "24", "--json"])
            .arg(&json),
    );
    let cli: Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("JSON");

    let out = run_calibrator(
        &dir,
        "    model: 24\n",
        &[("calibration", None), ("calibration_val", None)],
    );
    let got = out.diagnosis.unwrap_or_else(|| {
        panic!(
            "no Diagnosis from the calibrator; its report: {}",
            out.report
        )
    });

    let truth: Value = serde_json::from_str(
        &std::fs::read_to_string(repo_root().join("bags/calibration.truth.json")).expect("truth"),
    )
    .expect("truth JSON");
    let hidden: Vec<&str> = truth["effects"]
        .as_array()
        .expect("effects")
        .iter()
        .filter_map(|e| e["effect"].as_str())
        .collect();
    assert_eq!(hidden, ["parallelogram"], "the effect the twin hid");
    assert_eq!(got.missing_effect, hidden[0]);
    assert_eq!(
        got.missing_effect,
        cli["missing_effect"].as_str().unwrap_or_default()
    );
    // µm in the JSON, m on the topic; both from the same core on the same numbers, up to
    // the mm -> m -> mm round trip of the CSVs.
    let close = |m: f64, um: &Value, what: &str| {
        let um = um.as_f64().unwrap_or_else(|| panic!("{what}: no number"));
        assert!(
            (m * 1e6 - um).abs() <= 1e-6 * um.abs().max(1.0),
            "{what}: calibrator {} um vs rpkm diagnose {um} um",
            m * 1e6
        );
    };
    let base = &cli["baseline"];
    close(
        got.baseline_cal_rms,
        &base["cal_rms_um"],
        "baseline cal RMS",
    );
    close(
        got.baseline_val_rms,
        &base["val_rms_um"],
        "baseline val RMS",
    );
    close(got.noise_floor, &base["noise_floor_um"], "noise floor");
    let want = cli["candidates"].as_array().expect("candidates");
    let names = |v: &[String]| v.join(", ");
    let got_names: Vec<String> = got.candidates.iter().map(|c| c.effect.clone()).collect();
    let want_names: Vec<String> = want
        .iter()
        .map(|c| c["effect"].as_str().expect("effect").to_owned())
        .collect();
    assert_eq!(
        names(&got_names),
        names(&want_names),
        "the same candidates in the same order"
    );
    for (g, w) in got.candidates.iter().zip(want) {
        let e = &g.effect;
        assert_eq!(
            g.significant,
            w["significant"].as_bool().expect("bool"),
            "{e}"
        );
        let f = w["explained_fraction"].as_f64().expect("fraction");
        assert!(
            (g.explained_fraction - f).abs() < 1e-6,
            "{e}: explained {} vs {f}",
            g.explained_fraction
        );
        close(
            g.val_rms_before,
            &w["val_rms_before_um"],
            &format!("{e} before"),
        );
        close(
            g.val_rms_after,
            &w["val_rms_after_um"],
            &format!("{e} after"),
        );
    }
}

/// What the calibrator published for one campaign.
struct CalibratorOutput {
    parameters: Parameters,
    diagnosis: Option<Diagnosis>,
    /// The calibrator's last /diagnostics message, for failure messages.
    report: String,
}

/// Launches the calibrator (`extra` lines appended to its wildcard parameter section),
/// replays `passes` (reference bag, optional `--topics`) in order, sends the end-of-campaign
/// marker and collects what it publishes.
fn run_calibrator(
    dir: &std::path::Path,
    extra: &str,
    passes: &[(&str, Option<&str>)],
) -> CalibratorOutput {
    std::fs::write(
        dir.join("params.yaml"),
        format!("/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n{extra}"),
    )
    .expect("params.yaml");
    let launch_file = dir.join("cal.launch.yaml");
    std::fs::write(
        &launch_file,
        "launch:\n  - node: {pkg: rpkm, exec: calibrator, param: [{from: params.yaml}]}\n",
    )
    .expect("launch file");

    let prefix = unique("bagcal");
    let observer = Transport::new(&TransportConfig::new(unique("bagcalobs")).ipc_prefix(&prefix))
        .expect("transport");
    let parameters = observer.subscriber(&topic::PARAMETERS).expect("sub");
    let diagnosis = observer.subscriber(&topic::DIAGNOSIS).expect("sub");
    let diagnostics = observer.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let end = observer.publisher(&topic::TCP_MEASUREMENT).expect("pub");
    let mut launched = Launch::start(&launch_file, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let deadline = Instant::now() + Duration::from_secs(60);
    'ready: loop {
        assert!(Instant::now() < deadline, "calibrator not reporting");
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            if d.status.iter().any(|s| s.name == "rpkm/calibrator") {
                break 'ready;
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    for (bag, topics) in passes {
        let mut cmd = rpkm();
        cmd.arg("replay")
            .arg(reference_bag(bag))
            .args(["--rate", "1000", "--ipc-prefix", &prefix]);
        if let Some(t) = topics {
            cmd.args(["--topics", t]);
        }
        let mut replay = Watched::spawn(&mut cmd);
        let status = replay.wait(Duration::from_secs(60));
        assert!(status.success(), "replay: {}", replay.seen.join("\n"));
    }
    // The end-of-campaign marker (what ingest sends at the end of a file).
    let marker = TcpMeasurement {
        setup: "__end_of_campaign__".into(),
        instrument: TcpMeasurement::NONE,
        ..Default::default()
    };
    end.publish(&marker).expect("publish the marker");
    let deadline = Instant::now() + Duration::from_secs(120);
    let got: Parameters = loop {
        assert!(
            Instant::now() < deadline,
            "no Parameters from the calibrator"
        );
        if let Some(p) = parameters.try_recv().expect("recv") {
            break p;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    // The Diagnosis follows the Parameters; the calibrator's own account (unpaired
    // measurements, ...) is kept for failure messages.
    let mut report = String::new();
    let mut got_diagnosis = None;
    let settle = Instant::now() + Duration::from_secs(30);
    while Instant::now() < settle && (got_diagnosis.is_none() || report.is_empty()) {
        if let Some(d) = diagnosis.try_recv().expect("recv") {
            got_diagnosis = Some(d);
        }
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            for s in d.status.iter().filter(|s| s.name == "rpkm/calibrator") {
                report = format!("{}: {:?}", s.message, s.values);
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    launched.stop();
    CalibratorOutput {
        parameters: got,
        diagnosis: got_diagnosis,
        report,
    }
}

/// Writes the true parameters of a truth file as a geometry file (name -> mm/rad).
fn geometry_file(truth: &Value, path: &std::path::Path) -> Params {
    let p = truth_params(truth);
    let by_name: serde_json::Map<String, Value> = NAMES
        .iter()
        .enumerate()
        .map(|(i, n)| ((*n).to_owned(), serde_json::json!(p[i])))
        .collect();
    std::fs::write(path, Value::Object(by_name).to_string()).expect("params file");
    p
}

#[test]
fn stream_bag_through_the_estimator_matches_the_core_and_the_truth() {
    let dir = scratch("nodes-stream");
    let truth: Value = serde_json::from_str(
        &std::fs::read_to_string(reference_bag("stream_8khz.truth.json")).expect("truth"),
    )
    .expect("JSON");
    let geometry = dir.join("true_params.json");
    let p = geometry_file(&truth, &geometry);
    std::fs::write(
        dir.join("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    geometry_file: {}\n    diagnostics_period_s: 0.2\n\
             tcp_estimator:\n  ros__parameters:\n    busy_poll_ms: 0.0\n",
            geometry.display()
        ),
    )
    .expect("params.yaml");
    // The estimator and, as an `executable` of the launch, a recorder of its output.
    let recorded = dir.join("recorded");
    let launch_file = dir.join("est.launch.yaml");
    std::fs::write(
        &launch_file,
        format!(
            "launch:\n  - node: {{pkg: rpkm, exec: tcp_estimator, param: [{{from: params.yaml}}]}}\n\
             \x20 - executable:\n      cmd: rpkm record --topics /rpkm/tcp_estimate --out {}\n\
             \x20     name: recorder\n",
            recorded.display()
        ),
    )
    .expect("launch file");
    let states: Vec<ActuatorState> =
        decode_all(&reference_bag("stream_8khz"), "/rpkm/actuator_state");
    let n = states.len();

    let prefix = unique("bagest");
    let observer = Transport::new(&TransportConfig::new(unique("bagestobs")).ipc_prefix(&prefix))
        .expect("transport");
    let estimates = observer.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let diagnostics = observer.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let mut launched = Launch::start(&launch_file, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    launched.wait_for("rpkm record: recording 1 topics", Duration::from_secs(60));
    let deadline = Instant::now() + Duration::from_secs(60);
    'ready: loop {
        assert!(Instant::now() < deadline, "tcp_estimator not reporting");
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            if d.status.iter().any(|s| s.name == "rpkm/tcp_estimator") {
                break 'ready;
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    // 8 kHz recorded, replayed at 1 kHz: what the estimator sustains on a loaded test machine.
    let mut replay = Watched::spawn(
        rpkm()
            .arg("replay")
            .arg(reference_bag("stream_8khz"))
            .args(["--rate", "0.125", "--ipc-prefix", &prefix]),
    );
    let mut got: Vec<Option<TcpEstimate>> = vec![None; n];
    let deadline = Instant::now() + Duration::from_secs(120);
    while got[n - 1].is_none() && Instant::now() < deadline {
        let mut idle = true;
        while let Some(e) = estimates.try_recv().expect("recv") {
            idle = false;
            let k = usize::try_from(e.seq).expect("seq");
            assert!(k < n, "seq {k} is not a sample of the bag");
            got[k] = Some(e);
        }
        while diagnostics.try_recv().expect("recv").is_some() {}
        if idle {
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    let status = replay.wait(Duration::from_secs(60));
    assert!(status.success(), "replay: {}", replay.seen.join("\n"));
    // Stopping the launch closes the recorder's bag: it holds what the observer received.
    launched.stop();
    let in_bag: Vec<TcpEstimate> = decode_all(&recorded, "/rpkm/tcp_estimate");
    let observed: Vec<&TcpEstimate> = got.iter().flatten().collect();
    assert_eq!(
        in_bag.len(),
        observed.len(),
        "the launch's recorder has every estimate the observer got"
    );
    for (r, o) in in_bag.iter().zip(&observed) {
        assert_eq!(r, *o, "recorded estimate {} as published", r.seq);
    }

    let lost = got.iter().filter(|e| e.is_none()).count();
    assert_eq!(lost, 0, "one TcpEstimate per sample");
    let hz = truth["stream"]["hz"].as_f64().expect("hz");
    for (k, (s, e)) in states.iter().zip(&got).enumerate() {
        let Some(e) = e else { continue };
        assert_eq!(
            e.stamp, s.stamp,
            "sample {k}: the estimate carries its sample's stamp"
        );
        let q = s.position.map(|v| v * 1e3);
        let rigid = rpkm_core::geometry::fgm(&p, rpkm_core::params::Model::M29, q[0], q[3])
            .expect("core fgm");
        assert!(
            (e.x * 1e3 - rigid.x()).abs() < 1e-6 && (e.y * 1e3 - rigid.y()).abs() < 1e-6,
            "sample {k}: estimate ({}, {}) mm vs core fgm ({}, {}) mm",
            e.x * 1e3,
            e.y * 1e3,
            rigid.x(),
            rigid.y()
        );
        // The truth: the programmed circle (radius 100 mm around (0, 1700) mm, one turn per
        // 2 s), missed by the controller's parameter error only.
        let a = std::f64::consts::TAU * (k as f64 / hz) / 2.0;
        let (xc, yc) = (100.0 * a.cos(), 1700.0 + 100.0 * a.sin());
        let miss = ((e.x * 1e3 - xc).powi(2) + (e.y * 1e3 - yc).powi(2)).sqrt();
        assert!(miss < 1.0, "sample {k}: {miss} mm off the programmed point");
    }
}
