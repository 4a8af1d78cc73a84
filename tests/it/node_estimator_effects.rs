//! A written effect calibrated and applied node to node (issue 26): `rpkm launch` starts
//! ingest (a twin's calibration campaign), the calibrator, the tcp_estimator and the
//! preload_monitor, all three with the same `effects_file` (`dq4: "-b * dir_q4"`). The twin's
//! carrier 4 has lost motion (`EffectKind::LostMotionQ4`, its own implementation, not the
//! expression). Checked against the twin's truth, never against the nodes' arithmetic:
//! - the Parameters the calibrator publishes carry `lost_motion_q4.b`, the twin's within
//!   0.1 µm (its σ on this campaign is about 0.02 µm: core/tests/it/written_effects.rs);
//! - the estimator and the monitor take them (their logs name the effect and its value);
//! - on drive states of the same machine moving back and forth afterwards, the estimator's
//!   TCP is near the twin's true TCP, and nearer than the same published geometry without
//!   the effect (the core's forward model at the encoders), which is off by the lost motion.

use crate::node_support;

use std::collections::HashMap;
use std::time::{Duration, Instant};

use node_support::{launch_from_params, unique, Launch, TempDir};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::geometry::fgm;
use rpkm_core::params::{index_of, unit, Model, Params, Unit};
use rpkm_msgs::{ActuatorState, Parameters, Time};
use rpkm_nodes::campaign_bag::stamp_from_seconds;
use rpkm_transport::{topic, Publisher, Subscriber, Transport, TransportConfig};
use rpkm_twin::{EffectKind, MachineState, Twin, TwinConfig};

/// The twin's lost motion of carrier 4, mm.
const B_MM: f64 = 0.02;
const EFFECTS: &str = "effects:\n  - name: lost_motion_q4\n    summary: carrier 4 lags behind \
                       its last move\n    params: {b: {unit: mm, prior: 0.01}}\n    \
                       dq4: \"-b * dir_q4\"\n";

fn twin() -> Twin {
    Twin::new(TwinConfig {
        seed: 8,
        effects: vec![(EffectKind::LostMotionQ4, B_MM)],
        noise: Some(rpkm_core::noise::NoiseModel::default()),
        ..Default::default()
    })
    .expect("twin")
}

fn write_launch(dir: &TempDir, campaign: &Campaign) -> std::path::PathBuf {
    std::fs::write(dir.path("cal.csv"), campaign.to_csv()).expect("campaign");
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
    launch_from_params(
        dir,
        "effects.launch.yaml",
        &dir.path("cal.csv"),
        &["calibrator", "tcp_estimator", "preload_monitor"],
    )
}

/// The first Parameters the calibrator publishes.
fn published(parameters: &Subscriber<Parameters>, launched: &Launch) -> Parameters {
    node_support::first_message(parameters, launched, "Parameters", Duration::from_secs(180))
}

/// Waits until node `node` logged that it took Parameters with the effect; the line.
fn taken_by(launched: &Launch, node: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(30);
    let prefix = format!("[{node}] ");
    loop {
        let log = launched.log.lock().map(|l| l.clone()).unwrap_or_default();
        if let Some(l) = log.iter().find(|l| {
            l.contains(&prefix) && (l.contains("parameters updated") || l.contains("ignoring"))
        }) {
            assert!(!l.contains("ignoring"), "{l}");
            return l.clone();
        }
        assert!(
            Instant::now() < deadline,
            "{node} did not take the Parameters: {log:?}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The check path: drive states of the machine moving back and forth over the workspace,
/// each with the twin's true state. `q4_before` is carrier 4's reading before the first
/// (the last state the nodes saw): where its lost motion's direction starts from.
fn check_path(twin: &Twin, q4_before: f64, t0: f64) -> Vec<(f64, MachineState)> {
    let targets = rpkm_core::design::validation(60, 0x26);
    let (mut last, mut dir) = (q4_before, 1.0);
    let mut out = Vec::with_capacity(targets.len());
    for (k, target) in targets.iter().enumerate() {
        let t = t0 + k as f64;
        let at = |enc4: f64| {
            twin.machine_state("check", target.x, target.y, t, [0.0, 0.0, 0.0, enc4], false)
                .expect("machine state")
        };
        // the command of carrier 4 (its encoder reads it), then the carrier lagging it
        let q4 = at(0.0).q[3];
        if (q4 - last).abs() > 1e-9 {
            dir = (q4 - last).signum();
        }
        last = q4;
        out.push((t, at(-B_MM * dir)));
    }
    out
}

fn state(seq: u64, t: f64, st: &MachineState) -> ActuatorState {
    ActuatorState {
        stamp: stamp_from_seconds(t).expect("stamp"),
        seq,
        position: st.q.map(|q| q / 1e3),
        force: st.f,
        follower: st.follower,
        ..Default::default()
    }
}

/// The estimates of the states, keyed by stamp: TCP (x, y) in mm.
fn estimates(
    states: &Publisher<ActuatorState>,
    estimates: &Subscriber<rpkm_msgs::TcpEstimate>,
    path: &[(f64, MachineState)],
) -> HashMap<Time, [f64; 2]> {
    let ours: std::collections::HashSet<Time> = path
        .iter()
        .map(|(t, _)| stamp_from_seconds(*t).expect("stamp"))
        .collect();
    let mut out = HashMap::new();
    for (k, (t, st)) in path.iter().enumerate() {
        states
            .publish(&state(1_000_000 + k as u64, *t, st))
            .expect("publish");
        // paced: a state lost on the best-effort topic would change a direction
        std::thread::sleep(Duration::from_millis(5));
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    while out.len() < path.len() && Instant::now() < deadline {
        while let Some(e) = estimates.try_recv().expect("recv") {
            if ours.contains(&e.stamp) {
                out.insert(e.stamp, [e.x * 1e3, e.y * 1e3]);
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    out
}

/// RMS (µm) of error vectors (mm) less their mean: a calibration from relative instruments
/// leaves the machine's frame where its start put it, which moves every TCP alike.
fn spread_um(errors: &[[f64; 2]]) -> f64 {
    let n = errors.len() as f64;
    let mean = [0, 1].map(|a| errors.iter().map(|e| e[a]).sum::<f64>() / n);
    let ss: f64 = errors
        .iter()
        .map(|e| (e[0] - mean[0]).powi(2) + (e[1] - mean[1]).powi(2))
        .sum();
    (ss / n).sqrt() * 1e3
}

#[test]
fn the_estimator_applies_the_calibrated_written_effect() {
    let mut twin = twin();
    let campaign = twin
        .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])
        .expect("campaign");
    let dir = TempDir::new("effects_follow");
    let launch = write_launch(&dir, &campaign);
    let prefix = unique("effects");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let parameters = t.subscriber(&topic::PARAMETERS).expect("sub");
    let tcp = t.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let states = t.publisher(&topic::ACTUATOR_STATE).expect("pub");
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);

    let p = published(&parameters, &launched);
    assert_eq!(p.active_effects, ["lost_motion_q4"]);
    assert_eq!(p.effect_parameter_names, ["lost_motion_q4.b"]);
    let b = p.effect_parameter_values[0] * 1e3;
    assert!(
        (b - B_MM).abs() < 1e-4,
        "published b = {b} mm, the twin's {B_MM} mm"
    );
    let est_line = taken_by(&launched, "tcp_estimator");
    let mon_line = taken_by(&launched, "preload_monitor");
    for line in [&est_line, &mon_line] {
        assert!(line.contains("with effects lost_motion_q4 (b = "), "{line}");
    }

    // the states of a path of the same machine, after the calibration campaign's
    let last = campaign.poses.last().expect("poses");
    let path = check_path(&twin, last.q[3], last.t + 100.0);
    let got = estimates(&states, &tcp, &path);
    launched.stop();
    assert_eq!(got.len(), path.len(), "an estimate of every check state");

    // the published geometry (mm, rad) without the effect: the core's forward model at the
    // encoders (q2, q3 follow: no preload, the elastic model is the rigid one)
    let mut geometry = Params::nominal();
    for (name, v) in p.names.iter().zip(&p.values) {
        let i = index_of(name).expect("a parameter name");
        geometry[i] = match unit(i) {
            Unit::Mm => v * 1e3,
            Unit::Rad => *v,
        };
    }
    let (mut with, mut without) = (Vec::new(), Vec::new());
    for (t, st) in &path {
        let e = got[&stamp_from_seconds(*t).expect("stamp")];
        with.push([e[0] - st.tcp.x, e[1] - st.tcp.y]);
        let r = fgm(&geometry, Model::M29, st.q[0], st.q[3]).expect("forward model");
        without.push([r.x() - st.tcp.x, r.y() - st.tcp.y]);
    }
    let (with, without) = (spread_um(&with), spread_um(&without));
    eprintln!(
        "published b = {:.3} µm; TCP error against the twin's truth less its mean (what no \
         relative instrument sees), RMS over {} states: {with:.2} µm with the effect, \
         {without:.2} µm without",
        b * 1e3,
        path.len()
    );
    assert!(
        with < 0.25 * without,
        "with the effect {with:.2} µm, without {without:.2} µm"
    );
    assert!(with < 2.0, "with the effect {with:.2} µm");
}
