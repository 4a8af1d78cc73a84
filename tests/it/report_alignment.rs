//! The error-vector maps of the report show what the independent simulator hid: on its
//! `alignment` campaign (`../shared/campaigns/foreign/alignment`, laser tracker rotated by a
//! small angle about z, the angle in its truth.json) the tracker's arrows of the geometric
//! model grow with the distance from the reset pose, perpendicular to the radius; with
//! `instrument_alignment` in the model they are noise, and the effect's angle is the truth's.
//! Checked on the numbers behind the arrows (`report.json`) and on the arrows the page draws
//! (their titles carry the same numbers). Required under CI; skipped where the folder is not
//! beside the clone.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::foreign_support;

use foreign_support::json;

fn alignment() -> Option<PathBuf> {
    foreign_support::dataset("alignment")
}

/// What the tracker's arrows show: Pearson r of |arrow| with the distance from the reset
/// pose, the rotation (µrad) a rigid turn about the reset pose fits to them (Σ r × e / Σ |r|²),
/// the radial scale (µm/m) it fits likewise, and how many.
struct Arrows {
    r_length_distance: f64,
    rotation_urad: f64,
    radial_um_per_m: f64,
    count: usize,
}

fn arrows(vectors: &serde_json::Value) -> Arrows {
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().expect(k);
    let lt: Vec<&serde_json::Value> = vectors
        .as_array()
        .expect("vectors")
        .iter()
        .filter(|v| v["instrument"] == "lt")
        .collect();
    let (mut dist, mut len) = (Vec::new(), Vec::new());
    let (mut cross, mut dot, mut rr) = (0.0, 0.0, 0.0);
    for v in &lt {
        let (rx, ry) = (f(v, "x") - f(v, "reset_x"), f(v, "y") - f(v, "reset_y"));
        let (ex, ey) = (f(v, "dx_um"), f(v, "dy_um"));
        dist.push(rx.hypot(ry));
        len.push(ex.hypot(ey));
        cross += rx * ey - ry * ex;
        dot += rx * ex + ry * ey;
        rr += rx * rx + ry * ry;
    }
    Arrows {
        r_length_distance: pearson(&dist, &len),
        // µm per mm is mrad: x 1e3 for µrad
        rotation_urad: cross / rr * 1e3,
        radial_um_per_m: dot / rr * 1e3,
        count: lt.len(),
    }
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

#[test]
fn tracker_arrows_show_the_hidden_rotation_before_and_noise_after() {
    let Some(ds) = alignment() else { return };
    let out = tempfile::tempdir().expect("tempdir");
    let report = out.path().join("report");
    let diagnosis = out.path().join("d.json");
    let run = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .arg("diagnose")
        .arg(ds.join("cal.csv"))
        .arg("--validate")
        .arg(ds.join("val.csv"))
        .arg("--json")
        .arg(&diagnosis)
        .arg("--report")
        .arg(&report)
        .output()
        .expect("run rpkm");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let truth_urad = json(&ds.join("truth.json"))["hidden_effects"]["instrument_alignment"]
        .as_f64()
        .expect("hidden rotation")
        * 1e6;
    let r = json(&report.join("report.json"));
    assert_eq!(r["effects_after"][0], "instrument_alignment", "{stdout}");
    let before = arrows(&r["error_vectors"]["before"]);
    let after = arrows(&r["error_vectors"]["after"]);
    let estimate = tracker_angle_urad(&json(&diagnosis));
    println!(
        "|arrow| vs distance r: {:.3} -> {:.3}; turn of the arrows {:.2} -> {:.2} urad, radial {:.2} -> {:.2} um/m; {} arrows; instrument_alignment theta_lt {:.1} +- {:.1} urad (truth {truth_urad:.1})",
        before.r_length_distance,
        after.r_length_distance,
        before.rotation_urad,
        after.rotation_urad,
        before.radial_um_per_m,
        after.radial_um_per_m,
        before.count,
        estimate.0,
        estimate.1
    );
    assert!(before.count >= 40 && after.count == before.count);
    // before: arrows grow with the distance and turn about the reset pose the way the tracker
    // is turned (the geometric calibration takes part of the turn into the machine frame);
    // perpendicular to the radius: no radial part
    assert!(before.r_length_distance > 0.5);
    assert!(before.rotation_urad > 0.2 * truth_urad && before.rotation_urad < 1.1 * truth_urad);
    assert!(before.radial_um_per_m.abs() < 0.2 * before.rotation_urad);
    // after: no growth with the distance, no turn left
    assert!(after.r_length_distance.abs() < 0.3);
    assert!(after.rotation_urad.abs() < 0.05 * truth_urad);
    // the angle the effect identifies is the truth's (3 sigma); its sign convention is the
    // correction's, the opposite of the instrument's turn
    assert!((-estimate.0 - truth_urad).abs() < 3.0 * estimate.1);
    assert_drawn(&report.join("report.html"), &r["error_vectors"]["before"]);
}

/// The tracker's angle instrument_alignment identifies (µrad) and its σ.
fn tracker_angle_urad(d: &serde_json::Value) -> (f64, f64) {
    let c = d["candidates"]
        .as_array()
        .expect("candidates")
        .iter()
        .find(|c| c["effect"] == "instrument_alignment")
        .expect("instrument_alignment tried");
    let p = c["params"]
        .as_array()
        .expect("params")
        .iter()
        .find(|p| p["name"] == "theta_lt")
        .expect("theta_lt");
    assert_eq!(p["unit"], "mrad");
    let f = |k: &str| p[k].as_f64().expect(k) * 1e3;
    (f("value"), f("sigma"))
}

/// Every vector of the JSON is an arrow of the page, its title carrying its line and error.
fn assert_drawn(page: &Path, vectors: &serde_json::Value) {
    let html = std::fs::read_to_string(page).expect("report page");
    for v in vectors.as_array().expect("vectors") {
        let title = format!(
            "<title>line {}: x {:.1}, y {:.1} mm: error ({:.2}, {:.2}) µm",
            v["line"],
            v["x"].as_f64().expect("x"),
            v["y"].as_f64().expect("y"),
            v["dx_um"].as_f64().expect("dx"),
            v["dy_um"].as_f64().expect("dy")
        );
        assert!(html.contains(&title), "no arrow {title}");
    }
}
