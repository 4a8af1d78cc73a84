//! The live estimator against a truth it did not write: the foreign simulator's `null`
//! campaign (`../shared/campaigns/foreign/null`: 643 poses of laser tracker, grid encoder,
//! ball-bar and self-calibration setups, 1 m jumps between them, q2/q3 followers) streamed by
//! ingest into the real tcp_estimator process, whose geometry is the foreign machine's true
//! parameters (`truth.json` `P_true`). Every TcpEstimate must lie on the foreign simulator's
//! true pose of its row (`true_pose_cal`: x, y, ψ), to what its own encoder noise (0.5 µm)
//! allows, flagged converged, with ψ wrapped. The foreign simulator closes the loop its own
//! way (least squares over the active rods), so this checks the estimator's solver, the
//! ingest path and the units end to end. The tolerance bites: the nominal geometry's rigid
//! model misses the same poses by ten times it (asserted). Required under CI.

use crate::foreign_support;
use crate::node_support;

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use node_support::{launch_from_params, unique, Launch, TempDir};
use rpkm_core::campaign::Campaign;
use rpkm_core::geometry::fgm;
use rpkm_core::params::{Model, Params, NAMES};
use rpkm_transport::{topic, Transport, TransportConfig};

const RATE_HZ: f64 = 400.0;
/// Largest distance (mm) of an estimate from the true pose: the 0.5 µm encoder noise of q1
/// and q4 through the TCP's sensitivity (below 3 over the workspace), with margin.
const TOL_MM: f64 = 0.010;
/// Largest ψ error (rad): the same noise over the rods' ~1 m lever.
const TOL_PSI: f64 = 2e-5;

/// The foreign truth: its true parameters (our names: `g1`, `g2` are γ1, γ2) and the true
/// pose (x, y mm; ψ rad) of every row of cal.csv.
fn truth(dir: &Path) -> (Params, Vec<[f64; 3]>) {
    let t = foreign_support::json(&dir.join("truth.json"));
    let mut p = Params::nominal();
    for (i, name) in NAMES.iter().enumerate() {
        let key = match *name {
            "gamma1" => "g1",
            "gamma2" => "g2",
            n => n,
        };
        p[i] = t["P_true"][key]
            .as_f64()
            .expect("P_true names every parameter");
    }
    let poses = t["true_pose_cal"]
        .as_array()
        .expect("true_pose_cal")
        .iter()
        .map(|v| {
            let at = |k: usize| v[k].as_f64().expect("a number");
            [at(0), at(1), at(2)]
        })
        .collect();
    (p, poses)
}

/// `geometry_file` of the estimator: name -> value in mm/rad, as `rpkm calibrate --json`
/// writes its parameters.
fn geometry_json(p: &Params) -> String {
    let entries: Vec<String> = NAMES
        .iter()
        .enumerate()
        .map(|(i, n)| format!("\"{n}\": {:.12}", p[i]))
        .collect();
    format!("{{\"parameters\": {{{}}}}}", entries.join(", "))
}

fn write_launch(dir: &TempDir, csv: &Path, geometry: &Path) -> PathBuf {
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.2\n\
             ingest:\n  ros__parameters:\n    rate_hz: {RATE_HZ}\n    start_delay_s: 1.5\n\
             tcp_estimator:\n  ros__parameters:\n    geometry_file: {}\n",
            geometry.display()
        ),
    )
    .expect("params");
    launch_from_params(dir, "foreign.launch.yaml", csv, &["tcp_estimator"])
}

/// Distance (mm) of the nominal geometry's rigid model from the truth, per pose: what a wrong
/// geometry gives, so that the tolerance is shown to discriminate.
fn nominal_miss_mm(c: &Campaign, truth: &[[f64; 3]]) -> f64 {
    let nominal = Params::nominal();
    c.poses
        .iter()
        .zip(truth)
        .map(|(pose, t)| {
            let r = fgm(&nominal, Model::M29, pose.q[0], pose.q[3]).expect("nominal rigid model");
            (r.x() - t[0]).hypot(r.y() - t[1])
        })
        .fold(0.0, f64::max)
}

#[test]
fn live_estimates_lie_on_the_foreign_simulators_true_poses() {
    let Some(ds) = foreign_support::dataset("null") else {
        return;
    };
    let csv = ds.join("cal.csv");
    let text = std::fs::read_to_string(&csv).expect("cal.csv");
    let c = Campaign::parse(&text, "foreign null").expect("foreign campaign");
    let (p_true, poses) = truth(&ds);
    assert_eq!(poses.len(), c.poses.len(), "a true pose per row");
    let nominal_miss = nominal_miss_mm(&c, &poses);
    assert!(
        nominal_miss > 10.0 * TOL_MM,
        "the nominal geometry misses by only {nominal_miss} mm: the check would not bite"
    );

    let dir = TempDir::new("foreign");
    let geometry = dir.path("p_true.json");
    std::fs::write(&geometry, geometry_json(&p_true)).expect("geometry file");
    let launch = write_launch(&dir, &csv, &geometry);
    let prefix = unique("foreign");
    let t = Transport::new(&TransportConfig::new(unique("obs")).ipc_prefix(&prefix))
        .expect("transport");
    let estimates = t.subscriber(&topic::TCP_ESTIMATE).expect("sub");
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let n = c.poses.len();
    let mut seen = vec![false; n];
    let (mut worst_mm, mut worst_psi, mut sum2, mut count) = (0.0f64, 0.0f64, 0.0, 0usize);
    let deadline = Instant::now() + Duration::from_secs(90);
    while Instant::now() < deadline && !seen.iter().all(|s| *s) {
        let Some(e) = estimates.try_recv().expect("recv") else {
            std::thread::sleep(Duration::from_millis(1));
            continue;
        };
        // ingest numbers the rows' states 1, 2, ... in file order
        let k = usize::try_from(e.seq).expect("seq") - 1;
        let truth = poses.get(k).expect("seq names a row");
        let d = (e.x * 1e3 - truth[0]).hypot(e.y * 1e3 - truth[1]);
        let dpsi = (e.psi - truth[2]).abs();
        assert!(
            d < TOL_MM && dpsi < TOL_PSI,
            "row {} ({} setup): {d:.4} mm, {dpsi:.2e} rad off the foreign true pose {truth:?}",
            k + 1,
            c.poses[k].setup
        );
        assert!(e.converged, "row {}: flagged not converged: {e:?}", k + 1);
        assert!(e.psi > -PI && e.psi <= PI, "row {}: ψ {}", k + 1, e.psi);
        worst_mm = worst_mm.max(d);
        worst_psi = worst_psi.max(dpsi);
        sum2 += d * d;
        count += 1;
        seen[k] = true;
    }
    launched.stop();
    let missing: Vec<usize> = (0..n).filter(|&k| !seen[k]).map(|k| k + 1).collect();
    assert!(missing.is_empty(), "no estimate for rows {missing:?}");
    eprintln!(
        "{count} estimates: worst {:.2} µm, RMS {:.2} µm, worst ψ {:.1} µrad; \
         nominal geometry misses by up to {:.0} µm",
        worst_mm * 1e3,
        (sum2 / count as f64).sqrt() * 1e3,
        worst_psi * 1e6,
        nominal_miss * 1e3
    );
}
