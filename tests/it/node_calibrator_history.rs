//! The calibrator launched with `history` (an SQLite file) and `history_machine`: two
//! campaigns of the history tests' machine (history_support: before and after rod 3 is bent
//! by 0.1 mm) streamed by ingest, one launch each. Each calibration is recorded; the second's
//! /diagnostics status says what changed since the first: l3, by the crash, and nothing else.

use crate::history_support::scenario;
use crate::node_support::{launch_from_params, unique, Launch, TempDir};
use rpkm_history::Store;
use rpkm_transport::{topic, Transport, TransportConfig};
use std::time::{Duration, Instant};

/// One launch of ingest (campaign `k`) and the calibrator; the calibrator's /diagnostics
/// message that tells its calibration.
fn calibrate(dir: &TempDir, k: usize, db: &str) -> String {
    std::fs::write(
        dir.path("params.yaml"),
        format!(
            "/**:\n  ros__parameters:\n    diagnostics_period_s: 0.5\n\
             ingest:\n  ros__parameters:\n    rate_hz: 2000.0\n    start_delay_s: 1.0\n\
             calibrator:\n  ros__parameters:\n    history: {db}\n    history_machine: cell-7\n"
        ),
    )
    .expect("params");
    let launch = launch_from_params(
        dir,
        "h.launch.yaml",
        &scenario().campaign(k),
        &["calibrator"],
    );
    let prefix = unique("hist");
    let t = Transport::new(&TransportConfig::new(unique("histobs")).ipc_prefix(&prefix))
        .expect("transport");
    let diagnostics = t.subscriber(&topic::DIAGNOSTICS).expect("sub");
    let mut launched = Launch::start(&launch, &[("RPKM_IPC_PREFIX", prefix.as_str())]);
    let deadline = Instant::now() + Duration::from_secs(300);
    let said = 'wait: loop {
        assert!(Instant::now() < deadline, "no calibration on /diagnostics");
        while let Some(d) = diagnostics.try_recv().expect("recv") {
            if let Some(s) = d
                .status
                .iter()
                .find(|s| s.name == "rpkm/calibrator" && s.message.contains("history:"))
            {
                break 'wait s.message.clone();
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    launched.stop();
    said
}

#[test]
fn the_calibrator_records_and_says_what_changed_since_the_previous_calibration() {
    let dir = TempDir::new("calhist");
    let db = dir.path("cell.db").to_string_lossy().into_owned();
    let first = calibrate(&dir, 0, &db);
    assert!(
        first.contains("history: recorded as 1; the first calibration of cell-7"),
        "{first}"
    );
    let second = calibrate(&dir, 1, &db);
    eprintln!("{second}");
    let since = second
        .split("since the previous calibration (")
        .nth(1)
        .unwrap_or_else(|| panic!("{second}"));
    // "2026-..-.. ..:.. UTC): l3 +0.1xx mm ± 0.0xx (zσ)" and nothing else
    let moved = since.split("): ").nth(1).expect("what moved");
    assert!(
        moved.starts_with("l3 +0.1") || moved.starts_with("l3 +0.0"),
        "{second}"
    );
    assert_eq!(moved.matches(" mm ± ").count(), 1, "{second}");
    // and the whole machine's statement: the crash is beyond chance either way
    assert!(
        moved.contains("; the machine changed: largest single change l3 ")
            && moved.contains("reaches by chance")
            && moved.contains("; joint χ² "),
        "{second}"
    );
    let change: f64 = moved[3..]
        .split(' ')
        .next()
        .expect("number")
        .parse()
        .expect("mm");
    assert!((change - 0.1).abs() < 0.03, "{second}");
    let mut store = Store::open(&db).expect("open");
    let cals = store.calibrations("cell-7").expect("read");
    assert_eq!(cals.len(), 2);
    assert!(cals.iter().all(|c| c.record.source == "rpkm/calibrator"));
    assert!(cals.iter().all(|c| c.record.verdict.is_some()), "diagnosed");
}
