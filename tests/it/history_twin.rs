//! The machine's history on SQLite, end to end: twelve calibrations of one twin machine
//! recorded by `rpkm calibrate --history` (history_support: a crash of rod 3, then l1
//! creeping), read back by `rpkm history`: l3 flagged between the first two and nothing
//! else, the l1 trend with its significance and tolerance crossing against the truth; the
//! CSV holds every calibration, the report's charts show the crash and the creep.

use crate::history_support::{self, record, scenario, CALIBRATIONS, MACHINE};
use std::process::Command;

#[test]
fn twelve_calibrations_name_the_crash_and_the_creep() {
    let dir = tempfile::tempdir().expect("tempdir");
    let db = dir.path().join("machine.db");
    let db = db.to_string_lossy().into_owned();
    for k in 0..CALIBRATIONS {
        let said = record(&db, k);
        assert!(
            said.contains(&format!("recorded as calibration {}", k + 1)),
            "{said}"
        );
    }
    // recording a calibration again (a retried write) keeps it once
    assert!(record(&db, 3).contains("already recorded"));
    history_support::check(&db, dir.path());
    let (csv, report) = (dir.path().join("h.csv"), dir.path().join("report"));
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args([
            "history",
            &db,
            "--machine",
            MACHINE,
            "--from",
            "1",
            "--to",
            "2",
            "--csv",
        ])
        .arg(&csv)
        .arg("--report")
        .arg(&report)
        .output()
        .expect("rpkm history");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    check_csv(&std::fs::read_to_string(&csv).expect("csv"));
    // without --machine: the machines recorded; a path that is no history: exit 2
    let list = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args(["history", &db])
        .output()
        .expect("rpkm history");
    assert_eq!(
        String::from_utf8_lossy(&list.stdout),
        "scissors-1: 12 calibrations\n"
    );
    let missing = dir.path().join("no.db");
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .arg("history")
        .arg(&missing)
        .output()
        .expect("rpkm history");
    assert_eq!(out.status.code(), Some(2));
    assert!(!missing.exists(), "reading made a history");
    check_report(&std::fs::read_to_string(report.join("history.html")).expect("report"));
}

/// The effects in the model are recorded as the calibration file writes them: one
/// calibration with parallelogram, its history record's effects the `effects` of its --json.
#[test]
fn the_history_records_the_effects_as_the_calibration_file_writes_them() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (db, json) = (dir.path().join("m.db"), dir.path().join("cal.json"));
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .arg("calibrate")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/bags/demo/campaign.csv"
        ))
        .args(["--effects", "parallelogram"])
        .arg("--json")
        .arg(&json)
        .arg("--history")
        .arg(&db)
        .args(["--machine", "cell-1", "--at", "2026-03-01"])
        .output()
        .expect("rpkm calibrate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("cal.json")).expect("JSON");
    let mut store = rpkm_history::Store::open(&db.to_string_lossy()).expect("history");
    let recorded = store.calibrations("cell-1").expect("calibrations");
    assert_eq!(recorded.len(), 1);
    let effects = &recorded[0].record.effects;
    assert_eq!(effects, &file["effects"]);
    // parallelogram's parameters, each with its value, σ and unit
    assert!(
        effects.as_array().is_some_and(|a| !a.is_empty()),
        "{effects}"
    );
}

/// A row per calibration; l1's column is the twin's l1 within 4σ, l3's jumps by the crash.
fn check_csv(csv: &str) {
    let s = scenario();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), CALIBRATIONS);
    let nominal = rpkm_core::params::Params::nominal();
    for (k, row) in rows.iter().enumerate() {
        let v: f64 = row[col("l1")].parse().expect("l1 determined");
        let sigma: f64 = row[col("l1_sigma")].parse().expect("σ");
        let truth = nominal[rpkm_core::params::L1] + s.l1_offset[k];
        assert!(
            (v - truth).abs() < 4.0 * sigma,
            "{k}: l1 {v} ± {sigma} vs {truth}"
        );
        assert!(
            row[col("held_out_rms_um")].parse::<f64>().is_ok(),
            "{row:?}"
        );
        // the joints a small campaign cannot see are left empty, not written as values
        assert_eq!(row[col("xa1r")], "", "{row:?}");
    }
    let l3 = |k: usize| rows[k][col("l3")].parse::<f64>().expect("l3");
    assert!((l3(1) - l3(0) - 0.1).abs() < 0.03);
}

/// The l1 chart: a point per calibration, the trend line and the crossing; the l3 chart; the
/// held-out RMS over time; the table of the crash's change flags l3 alone.
fn check_report(html: &str) {
    let chart = |name: &str| {
        let at = html
            .find(&format!("\n{name} from nominal\n</text>"))
            .unwrap_or_else(|| panic!("no {name} chart"));
        let end = html[at..].find("</svg>").expect("svg end") + at;
        &html[at..end]
    };
    let l1 = chart("l1");
    assert_eq!(l1.matches("class=\"point\"").count(), CALIBRATIONS);
    assert_eq!(l1.matches("class=\"trend\"").count(), 1);
    assert_eq!(l1.matches("class=\"crossing\"").count(), 1);
    assert_eq!(l1.matches("class=\"bound\"").count(), 2);
    let l3 = chart("l3");
    assert_eq!(l3.matches("class=\"point\"").count(), CALIBRATIONS);
    assert_eq!(
        l3.matches("class=\"trend\"").count(),
        0,
        "l3 does not creep"
    );
    assert!(html.contains("Held-out TCP RMS"));
    let flagged: Vec<&str> = html
        .split("<tr class=\"flag\"")
        .skip(1)
        .filter_map(|row| row.split("<td>").nth(1)?.split("</td>").next())
        .collect();
    assert_eq!(flagged, ["l3"], "the crash's change flags l3 alone");
    assert!(html.contains("l1 creeps +"));
}
