//! The store on SQLite: a record reads back equal to what was written (the covariance to the
//! bit), a retried write records once, events keep their order, and a database of a newer
//! schema is refused.

use crate::{CalibrationRecord, CampaignId, EventKind, EventRecord, NoiseLevel, Store, StoreError};
use nalgebra::SMatrix;
use rpkm_core::params::{Model, Params, L3, N_PARAMS};

pub fn record(machine: &str, at_s: i64) -> CalibrationRecord {
    let mut params = Params::nominal();
    params[L3] += 0.1 + 1e-17 * at_s as f64;
    CalibrationRecord {
        machine: machine.to_owned(),
        at_s,
        source: "rpkm calibrate".to_owned(),
        campaign: CampaignId {
            name: "c.csv".to_owned(),
            digest: format!("{at_s:064x}"),
            poses: 236,
            rows: 708,
        },
        model: Model::M29,
        effects: serde_json::json!([]),
        params,
        covariance: SMatrix::from_fn(|i, j| {
            1e-4 / (1.0 + (i as f64 - j as f64).abs()) + f64::from(u8::from(i == j)) / 3e5
        }),
        tolerance: [0.1; N_PARAMS],
        determined: Some((14, 29)),
        noise: vec![NoiseLevel {
            group: "kgm".to_owned(),
            unit: "um".to_owned(),
            stated: 1.0,
            estimated: 1.0 / 3.0,
            dof: 412.5,
        }],
        chi2_per_dof: 1.02,
        held_out_rms_um: Some(20.35),
        verdict: None,
    }
}

#[test]
fn a_calibration_reads_back_as_written_and_records_once() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("m.db");
    let path = path.to_string_lossy();
    let mut store = Store::open(&path)?;
    let (a, b) = (
        record("cell-1", 1_772_323_200),
        record("cell-1", 1_772_928_000),
    );
    // written out of order: read back in time order
    let id_b = store.record_calibration(&b)?;
    let id_a = store.record_calibration(&a)?;
    assert!(id_a.is_some() && id_b.is_some());
    assert_eq!(store.record_calibration(&a)?, None, "a retried write");
    store.record_calibration(&record("cell-2", 1_772_323_200))?;
    drop(store);
    let mut store = Store::open(&path)?;
    let back = store.calibrations("cell-1")?;
    assert_eq!(back.len(), 2);
    assert_eq!(back[0].record, a);
    assert_eq!(back[1].record, b);
    assert_eq!(
        store.machines()?,
        [("cell-1".to_owned(), 2), ("cell-2".to_owned(), 1)]
    );
    let event = EventRecord {
        machine: "cell-1".into(),
        at_s: 1_772_400_000,
        source: "/rpkm/calibrator".into(),
        kind: EventKind::Step,
        parameter: Some("l3".into()),
        change: Some(0.1),
        sigma: Some(0.002),
        stream_t_s: Some(31.5),
        message: "step change at t = 31.5 s: l3 +100 µm".into(),
    };
    assert!(store.record_event(&event)?);
    assert!(!store.record_event(&event)?);
    let events = store.events("cell-1")?;
    assert_eq!(events.len(), 1);
    assert_eq!(events[0].record, event);
    Ok(())
}

/// An event kind this rpkm does not write (`drift`, which the record's doc once listed) is
/// refused when read back, naming the event: never read as another kind.
#[test]
fn an_event_of_an_unknown_kind_is_refused() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("m.db");
    let path = path.to_string_lossy();
    drop(Store::open(&path)?);
    let sqlite = |source| StoreError::Sqlite {
        location: path.to_string(),
        source,
    };
    let conn = rusqlite::Connection::open(path.as_ref()).map_err(sqlite)?;
    conn.execute(
        "INSERT INTO events (machine, at_s, source, kind, message) \
         VALUES ('cell-1', 0, 'test', 'drift', 'a drift')",
        [],
    )
    .map_err(sqlite)?;
    drop(conn);
    let got = Store::open(&path)?.events("cell-1");
    let Err(e @ StoreError::UnknownEventKind { .. }) = got else {
        panic!("expected the unknown kind refused, got {got:?}");
    };
    assert!(
        e.to_string()
            .ends_with("event 1: kind \"drift\", expected step or tie_settled"),
        "{e}"
    );
    assert_eq!(
        EventKind::ALL.map(|k| EventKind::parse(k.as_str())),
        EventKind::ALL.map(Some)
    );
    Ok(())
}

#[test]
fn a_store_of_a_newer_schema_is_refused() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("m.db");
    let path = path.to_string_lossy();
    drop(Store::open(&path)?);
    let conn = rusqlite::Connection::open(path.as_ref()).map_err(|source| StoreError::Sqlite {
        location: path.to_string(),
        source,
    })?;
    conn.execute(
        "INSERT INTO schema_version (version, applied_at_s) VALUES (99, 0)",
        [],
    )
    .map_err(|source| StoreError::Sqlite {
        location: path.to_string(),
        source,
    })?;
    match Store::open(&path) {
        Err(StoreError::NewerSchema {
            found: 99, known, ..
        }) => {
            assert_eq!(known, crate::schema::latest());
        }
        other => panic!(
            "expected a refusal, got {:?}",
            other.map(|s| s.location().to_owned())
        ),
    }
    Ok(())
}

#[test]
fn a_record_that_is_not_a_number_is_refused() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("m.db");
    let mut store = Store::open(&path.to_string_lossy())?;
    let mut r = record("cell-1", 1);
    r.params[L3] = f64::NAN;
    let e = store.record_calibration(&r).err().map(|e| e.to_string());
    assert!(
        e.as_deref()
            .is_some_and(|e| e.contains("cannot record: l3 = NaN")),
        "{e:?}"
    );
    assert!(store.calibrations("cell-1")?.is_empty());
    Ok(())
}
