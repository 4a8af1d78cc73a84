//! The calibrator diagnoses the model it calibrated (issue 36): launched with an
//! `effects_file` (lost motion of carrier 4, `dq4: "-b * dir_q4"`) on a twin whose carrier 4
//! lags by 20 µm, it publishes the held-out RMS of the model with the effect and a Diagnosis
//! of that model, and both are what `rpkm diagnose --model 29 --effects lost_motion_q4` says
//! of the same campaign: one held-out evaluation for the command line and the node. Before,
//! the node computed its held-out RMS from the geometry alone (the twin's lost motion left
//! in it) and diagnosed the geometry without the file's effect.

use crate::node_support;

use std::time::Duration;

use node_support::{first_message, launch_from_params, rpkm, unique, Launch, TempDir};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_msgs::{Diagnosis, Parameters};
use rpkm_transport::{topic, Subscriber, Transport, TransportConfig};
use rpkm_twin::{EffectKind, Twin, TwinConfig};

/// How long the node may take to calibrate and diagnose.
const WITHIN: Duration = Duration::from_secs(240);

/// The twin's lost motion of carrier 4, mm.
const B_MM: f64 = 0.02;
const EFFECTS: &str = "effects:\n  - name: lost_motion_q4\n    summary: carrier 4 lags behind \
                       its last move\n    params: {b: {unit: mm, prior: 0.01}}\n    \
                       dq4: \"-b * dir_q4\"\n";

#[test]
fn the_calibrator_diagnoses_its_model_as_the_command_line_does() {
    let mut twin = Twin::new(TwinConfig {
        seed: 36,
        effects: vec![(EffectKind::LostMotionQ4, B_MM)],
        noise: Some(rpkm_core::noise::NoiseModel::default()),
        ..Default::default()
    })
    .expect("twin");
    let cal = twin
        .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])
        .expect("campaign");
    let val = twin.validation(60).expect("validation");
    let dir = TempDir::new("diagnosis_effects");
    // the node takes one stream: the held-out setups (`val`) after the calibration's
    let whole = Campaign {
        poses: cal.poses.iter().chain(&val.poses).cloned().collect(),
        ..cal.clone()
    };
    std::fs::write(dir.path("whole.csv"), whole.to_csv()).expect("campaign");
    std::fs::write(dir.path("cal.csv"), cal.to_csv()).expect("campaign");
    std::fs::write(dir.path("val.csv"), val.to_csv()).expect("campaign");
    std::fs::write(dir.path("lost.yaml"), EFFECTS).expect("effects file");
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    effects_file: {}\n    diagnostics_period_s: 0.5\n\
             ingest:\n  ros__parameters:\n    rate_hz: 400.0\n    start_delay_s: 1.5\n",
            dir.path("lost.yaml").display()
        ),
    )
    .expect("params");
    let launch = launch_from_params(
        &dir,
        "diagnosis.launch.yaml",
        &dir.path("whole.csv"),
        &["calibrator"],
    );
    let prefix = unique("diagnosis");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let parameters: Subscriber<Parameters> = t.subscriber(&topic::PARAMETERS).expect("sub");
    let diagnosis: Subscriber<Diagnosis> = t.subscriber(&topic::DIAGNOSIS).expect("sub");
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let p = first_message(&parameters, &launched, "Parameters", WITHIN);
    let d = first_message(&diagnosis, &launched, "Diagnosis", WITHIN);
    launched.stop();

    let cli = diagnose(
        &dir,
        &[
            "--effects",
            "lost_motion_q4",
            "--effects-file",
            &dir.path("lost.yaml").display().to_string(),
        ],
        "d.json",
    );
    let cli_val_um = cli["baseline"]["val_rms_um"]
        .as_f64()
        .expect("held-out RMS");
    eprintln!(
        "node: held-out {:.3} µm (Parameters), {:.3} µm (Diagnosis), verdict {} ({:?}); \
         command line: held-out {cli_val_um:.3} µm, verdict {}",
        p.val_rms * 1e6,
        d.baseline_val_rms * 1e6,
        d.verdict_kind,
        d.model_effects,
        cli["verdict_kind"]
    );
    // the node diagnosed the model with the file's effect, as the command line
    assert_eq!(d.model_effects, ["lost_motion_q4"]);
    assert_eq!(cli["model_effects"], serde_json::json!(["lost_motion_q4"]));
    assert_eq!(cli["verdict_kind"].as_str(), Some(d.verdict_kind.as_str()));
    assert_eq!(
        cli["missing_effects"],
        serde_json::json!(d.missing_effects),
        "{}",
        d.verdict
    );
    // the same held-out RMS: the diagnosis's baseline and the published Parameters (the
    // node calibrates as the diagnosis does: tolerance prior, noise estimated, no outlier
    // removed); the stream's SI round trip leaves the last digits
    for node_um in [d.baseline_val_rms * 1e6, p.val_rms * 1e6] {
        assert!(
            (node_um - cli_val_um).abs() < 1e-3,
            "node {node_um} µm, command line {cli_val_um} µm"
        );
    }
    // and the effect is in it: the geometry alone, as the node had it, predicts worse
    let alone = diagnose(&dir, &[], "alone.json");
    let alone_um = alone["baseline"]["val_rms_relative_um"]
        .as_f64()
        .expect("RMS");
    let with_um = cli["baseline"]["val_rms_relative_um"]
        .as_f64()
        .expect("RMS");
    eprintln!("held-out RMS, each setup's zero removed: {alone_um:.2} µm without the effect, {with_um:.2} µm with it");
    assert!(
        with_um < 0.9 * alone_um,
        "{with_um} µm with, {alone_um} µm without"
    );
    assert_eq!(p.active_effects, ["lost_motion_q4"]);
    let b = p.effect_parameter_values[0] * 1e3;
    assert!(
        (b - B_MM).abs() < 1e-3,
        "published b = {b} mm, the twin's {B_MM} mm"
    );
}

/// `rpkm diagnose --model 29 EXTRA cal.csv --validate val.csv` in `dir`, its JSON.
fn diagnose(dir: &TempDir, extra: &[&str], name: &str) -> serde_json::Value {
    let json = dir.path(name);
    let out = std::process::Command::new(rpkm())
        .args(["diagnose", "--model", "29"])
        .args(extra)
        .arg(dir.path("cal.csv"))
        .arg("--validate")
        .arg(dir.path("val.csv"))
        .arg("--json")
        .arg(&json)
        .output()
        .expect("rpkm diagnose");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("json")
}
