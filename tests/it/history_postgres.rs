//! The machine's history on PostgreSQL: a server the test run starts (history_support), two
//! cells writing the twelve calibrations at once (`rpkm calibrate --history postgres://...`,
//! odd and even ones, each also recording the last one again): every record present once,
//! and `rpkm history` says what it says on SQLite.

use crate::history_support::{self, postgres::server, record, CALIBRATIONS};

#[test]
fn two_writers_at_once_record_every_calibration_once() {
    let Some(server) = server() else { return };
    let url = server.database("two_writers");
    let writers: Vec<std::thread::JoinHandle<Vec<String>>> = (0..2)
        .map(|w| {
            let url = url.clone();
            std::thread::spawn(move || {
                (0..CALIBRATIONS)
                    .filter(|k| k % 2 == w)
                    .chain([CALIBRATIONS - 1])
                    .map(|k| record(&url, k))
                    .collect()
            })
        })
        .collect();
    let said: Vec<String> = writers
        .into_iter()
        .flat_map(|w| w.join().expect("writer"))
        .collect();
    let recorded = said
        .iter()
        .filter(|s| s.contains("recorded as calibration"))
        .count();
    let again = said
        .iter()
        .filter(|s| s.contains("already recorded"))
        .count();
    assert_eq!((recorded, again), (CALIBRATIONS, 2), "{said:?}");
    let dir = tempfile::tempdir().expect("tempdir");
    history_support::check(&url, dir.path());
}
