//! The discovery loop on campaigns of an independent simulator (`../shared/campaigns/foreign`:
//! its own noise, thermal physics and seeds, with its truth), run as a user would: `rpkm
//! diagnose` with default options, the named effect added, again, until nothing is missing.
//! The truth is the foreign simulator's: which effect it hid, and the held-out noise floor
//! from its true poses. Required under CI; skipped where the folder is not beside the clone.

use std::path::{Path, PathBuf};
use std::process::Command;

mod foreign_support;

use foreign_support::{json, true_floor_um};

fn foreign() -> Option<PathBuf> {
    foreign_support::dataset("")
}

/// The loop: diagnose, add what was named, until nothing is named; (named, last JSON).
fn discovery_loop(ds: &Path, scratch: &Path) -> (Vec<String>, serde_json::Value) {
    let out = scratch.join("d.json");
    let mut named: Vec<String> = Vec::new();
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

fn check(name: &str, want: &[&str]) {
    let Some(root) = foreign() else { return };
    let ds = root.join(name);
    let scratch = std::env::temp_dir().join(format!("rpkm-foreign-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&scratch).expect("scratch");
    let (named, d) = discovery_loop(&ds, &scratch);
    let floor = true_floor_um(&ds);
    let val = d["baseline"]["val_rms_um"].as_f64().expect("held-out RMS");
    eprintln!(
        "{name}: named {named:?}, {} ; held-out {val:.1} um, true floor {floor:.1} um",
        d["verdict"]
    );
    assert_eq!(named, want, "{name}: {}", d["verdict"]);
    assert_eq!(
        d["verdict_kind"], "nothing_missing",
        "{name}: {}",
        d["verdict"]
    );
    assert!(
        val <= 1.5 * floor,
        "{name}: held-out {val} um, true floor {floor} um"
    );
}

#[test]
fn foreign_null_campaign_has_nothing_missing() {
    check("null", &[]);
}

#[test]
fn foreign_thermal_campaign_names_thermal_of_the_rods() {
    check("thermal", &["thermal"]);
    let Some(root) = foreign() else { return };
    // the foreign machine's rods alone expand, 11.5 ppm/K: the part kept and its coefficient
    let ds = root.join("thermal");
    let out = std::env::temp_dir().join(format!("rpkm-foreign-{}-alpha.json", std::process::id()));
    let o = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .arg("diagnose")
        .arg(ds.join("cal.csv"))
        .arg("--json")
        .arg(&out)
        .output()
        .expect("run rpkm");
    assert!(o.status.success());
    let d = json(&out);
    let c = d["candidates"]
        .as_array()
        .expect("candidates")
        .iter()
        .find(|c| c["effect"] == "thermal")
        .expect("thermal candidate");
    let truth = json(&ds.join("truth.json"))["hidden_effects"]["thermal"]
        .as_f64()
        .expect("alpha");
    for p in c["params"].as_array().expect("params") {
        let (part, identified) = (p["name"].as_str().expect("name"), p["identified"] == true);
        assert_eq!(identified, part == "alpha_rods", "{part}: {p}");
        if identified {
            let (v, s) = (
                p["value"].as_f64().expect("v"),
                p["sigma"].as_f64().expect("s"),
            );
            assert!((v - truth * 1e6).abs() <= 3.0 * s, "{v} ± {s} vs {truth}");
        }
    }
}

#[test]
fn foreign_alignment_campaign_names_the_tracker_alignment() {
    check("alignment", &["instrument_alignment"]);
}
