//! A writer killed mid-record (SIGKILL inside its transaction): the history opens, every
//! record committed before is there as written, nothing of the killed one, and the next
//! record goes in. On SQLite and on PostgreSQL (history_support's server). The writer is
//! this test binary run again as `history_kill::killed_writer`, which records a calibration
//! and an event in one batch and waits inside it to be killed.

use crate::history_support::postgres::server;
use nalgebra::SMatrix;
use rpkm_core::params::{Model, Params, L3, N_PARAMS};
use rpkm_history::{CalibrationRecord, CampaignId, EventKind, EventRecord, Store};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

const LOCATION: &str = "RPKM_HISTORY_KILLED_WRITER";

/// The `k`-th calibration of the test machine (a day apart, l3 growing).
fn calibration(k: i64) -> CalibrationRecord {
    let mut params = Params::nominal();
    params[L3] += 0.001 * k as f64;
    CalibrationRecord {
        machine: "killed".into(),
        at_s: 1_772_359_200 + 86_400 * k,
        source: "history_kill".into(),
        campaign: CampaignId {
            name: format!("c{k}.csv"),
            digest: format!("{k:064x}"),
            poses: 236,
            rows: 708,
        },
        model: Model::M29,
        effects: serde_json::json!([]),
        params,
        covariance: SMatrix::from_fn(|i, j| {
            if i == j {
                1e-5 * (1.0 + i as f64)
            } else {
                1e-7
            }
        }),
        tolerance: [0.1; N_PARAMS],
        determined: Some((14, 29)),
        noise: Vec::new(),
        chi2_per_dof: 1.0,
        held_out_rms_um: Some(20.0 + k as f64),
        verdict: Some("nothing missing".into()),
    }
}

/// The child: the fourth calibration and an event in one batch, then "inside" on stdout and
/// a wait to be killed inside the transaction.
#[test]
#[ignore = "the writer history_kill's tests start and kill"]
fn killed_writer() {
    let location = std::env::var(LOCATION).expect("run by writer_killed_mid_record_*");
    let mut store = Store::open(&location).expect("open");
    let _ = store.batch(|b| {
        b.calibration(&calibration(3))?;
        b.event(&EventRecord {
            machine: "killed".into(),
            at_s: 1_772_359_200 + 3 * 86_400,
            source: "history_kill".into(),
            kind: EventKind::Step,
            parameter: Some("l3".into()),
            change: Some(0.1),
            sigma: Some(0.002),
            stream_t_s: Some(1.0),
            message: "half-written".into(),
        })?;
        println!("inside");
        std::thread::sleep(Duration::from_secs(120));
        Ok(())
    });
    panic!("not killed within 120 s");
}

fn killed_mid_record(location: &str) {
    let mut store = Store::open(location).expect("open");
    for k in 0..3 {
        assert!(store
            .record_calibration(&calibration(k))
            .expect("record")
            .is_some());
    }
    drop(store);
    let mut child = Command::new(std::env::current_exe().expect("test binary"))
        .args([
            "history_kill::killed_writer",
            "--exact",
            "--ignored",
            "--nocapture",
        ])
        .env(LOCATION, location)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the writer");
    let out = child.stdout.take().expect("stdout");
    let inside = BufReader::new(out)
        .lines()
        .map_while(Result::ok)
        .any(|l| l.contains("inside"));
    assert!(inside, "the writer never got inside its record");
    child.kill().expect("SIGKILL");
    let _ = child.wait();
    let mut store = Store::open(location).expect("opens after the kill");
    let back = store.calibrations("killed").expect("read");
    let records: Vec<CalibrationRecord> = back.into_iter().map(|s| s.record).collect();
    assert_eq!(records, (0..3).map(calibration).collect::<Vec<_>>());
    assert!(store.events("killed").expect("events").is_empty());
    // the killed record was never committed: it goes in now
    assert!(store
        .record_calibration(&calibration(3))
        .expect("record")
        .is_some());
    assert_eq!(store.calibrations("killed").expect("read").len(), 4);
}

#[test]
fn writer_killed_mid_record_on_sqlite() {
    let dir = tempfile::tempdir().expect("tempdir");
    killed_mid_record(&dir.path().join("m.db").to_string_lossy());
}

#[test]
fn writer_killed_mid_record_on_postgres() {
    let Some(server) = server() else { return };
    killed_mid_record(&server.database("killed_writer"));
}
