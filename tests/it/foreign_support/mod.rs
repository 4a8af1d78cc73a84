//! The independent simulator's campaigns (`../shared/campaigns/foreign`, beside the clone,
//! not in the repository): where they are; whether a test runs without them is
//! `shared_support`'s decision.
#![allow(dead_code)] // each test file uses a part

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::shared_support;

/// The folder of the foreign data set `name` (`null`, `thermal`, `alignment`), or the whole
/// collection for `""`; `None` where it is not beside the clone (skipped or, under `CI=true`,
/// failed by `shared_support`).
pub fn dataset(name: &str) -> Option<PathBuf> {
    let relative = if name.is_empty() {
        "campaigns/foreign".to_owned()
    } else {
        format!("campaigns/foreign/{name}")
    };
    shared_support::path(&relative, "the development campaigns")
}

/// A JSON file of the data set (truth.json), or a failure naming it.
pub fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// RMS (µm) of the held-out readings against the foreign truth's poses: the noise floor.
pub fn true_floor_um(ds: &Path) -> f64 {
    let truth = json(&ds.join("truth.json"));
    let text = std::fs::read_to_string(ds.join("val.csv")).expect("val.csv");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).expect("column");
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let poses = truth["true_pose_val"].as_array().expect("true poses");
    let theta = truth["hidden_effects"]["instrument_alignment"]
        .as_f64()
        .unwrap_or(0.0);
    let (c, s) = (theta.cos(), theta.sin());
    let reset = rows
        .iter()
        .position(|r| r[col("reset")] == "1")
        .expect("reset");
    let at = |i: usize, k: usize| poses[i][k].as_f64().expect("number");
    let mut e = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        if i == reset || r[col("x")].is_empty() {
            continue;
        }
        let (dx, dy) = (at(i, 0) - at(reset, 0), at(i, 1) - at(reset, 1));
        let x: f64 = r[col("x")].parse().expect("x");
        let y: f64 = r[col("y")].parse().expect("y");
        e.push(c * dx + s * dy - x);
        e.push(-s * dx + c * dy - y);
    }
    1e3 * (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
}

/// The loop a user runs: diagnose, add what was named, until nothing new is named, from the
/// effects `start` (none: from nothing); (named, the last JSON).
pub fn discovery_loop(
    ds: &Path,
    scratch: &Path,
    start: &[&str],
) -> (Vec<String>, serde_json::Value) {
    let out = scratch.join("d.json");
    let mut named: Vec<String> = start.iter().map(|s| (*s).to_owned()).collect();
    loop {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_rpkm"));
        cmd.arg("diagnose")
            .arg(ds.join("cal.csv"))
            .arg("--validate")
            .arg(ds.join("val.csv"))
            .arg("--json")
            .arg(&out);
        if !named.is_empty() {
            cmd.args(["--effects", &named.join(",")]);
        }
        let o = cmd.output().expect("run rpkm");
        assert!(
            o.status.success(),
            "{cmd:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let d = json(&out);
        match d["missing_effect"].as_str() {
            Some(e) if !named.iter().any(|n| n == e) && named.len() < 3 => named.push(e.to_owned()),
            _ => return (named, d),
        }
    }
}
