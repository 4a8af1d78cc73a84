//! The history's schema, one for both databases, as numbered migrations: a database records
//! the highest it has applied (`schema_version`), and opening it applies the rest in order,
//! each in the transaction that records it. Two writers opening an empty database at once
//! migrate it once: SQLite's transaction takes the write lock at its start, PostgreSQL's an
//! advisory lock. A database with a migration this build does not know is refused, never
//! written.
//!
//! Times are UTC Unix seconds (`at_s`): `datetime(at_s, 'unixepoch')` in SQLite,
//! `to_timestamp(at_s)` in PostgreSQL. Lengths in mm, angles in rad, RMS in µm.

use crate::backend::{Dialect, Kind, Tx, Value};
use crate::error::StoreError;

/// One migration: its number and statements (`{id}`: the dialect's auto-numbered key).
pub struct Migration {
    pub version: i64,
    pub what: &'static str,
    pub statements: &'static [&'static str],
}

/// Every migration, in order.
pub const MIGRATIONS: &[Migration] = &[Migration {
    version: 1,
    what: "calibrations, their parameters and noise; online events",
    statements: &[
        "CREATE TABLE calibrations (
            id {id},
            machine TEXT NOT NULL,
            at_s BIGINT NOT NULL,
            source TEXT NOT NULL,
            campaign TEXT NOT NULL,
            campaign_digest TEXT NOT NULL,
            poses BIGINT NOT NULL,
            rows_used BIGINT NOT NULL,
            model BIGINT NOT NULL,
            effects TEXT NOT NULL,
            determined BIGINT,
            determined_of BIGINT,
            chi2_per_dof DOUBLE PRECISION NOT NULL,
            held_out_rms_um DOUBLE PRECISION,
            verdict TEXT,
            covariance TEXT NOT NULL,
            UNIQUE (machine, at_s, campaign_digest, source)
        )",
        "CREATE INDEX calibrations_by_machine ON calibrations (machine, at_s)",
        "CREATE TABLE parameters (
            calibration_id BIGINT NOT NULL REFERENCES calibrations (id) ON DELETE CASCADE,
            name TEXT NOT NULL,
            value DOUBLE PRECISION NOT NULL,
            sigma DOUBLE PRECISION NOT NULL,
            tolerance DOUBLE PRECISION NOT NULL,
            PRIMARY KEY (calibration_id, name)
        )",
        "CREATE TABLE noise (
            calibration_id BIGINT NOT NULL REFERENCES calibrations (id) ON DELETE CASCADE,
            noise_group TEXT NOT NULL,
            unit TEXT NOT NULL,
            stated DOUBLE PRECISION NOT NULL,
            estimated DOUBLE PRECISION NOT NULL,
            dof DOUBLE PRECISION NOT NULL,
            PRIMARY KEY (calibration_id, noise_group)
        )",
        "CREATE TABLE events (
            id {id},
            machine TEXT NOT NULL,
            at_s BIGINT NOT NULL,
            source TEXT NOT NULL,
            kind TEXT NOT NULL,
            parameter TEXT,
            change DOUBLE PRECISION,
            sigma DOUBLE PRECISION,
            stream_t_s DOUBLE PRECISION,
            message TEXT NOT NULL,
            UNIQUE (machine, at_s, source, kind, message)
        )",
        "CREATE INDEX events_by_machine ON events (machine, at_s)",
    ],
}];

/// The newest schema this build knows.
pub fn latest() -> i64 {
    MIGRATIONS.last().map_or(0, |m| m.version)
}

/// A key for PostgreSQL's advisory lock of the migrations ("rpkm").
const MIGRATION_LOCK: i64 = 0x7270_6b6d;

/// Brings the database in `tx` to the latest schema; the version it found.
pub fn migrate(tx: &mut dyn Tx, location: &str) -> Result<i64, StoreError> {
    let dialect = tx.dialect();
    if dialect == Dialect::Postgres {
        tx.execute(
            "SELECT pg_advisory_xact_lock(?)",
            &[Value::Int(Some(MIGRATION_LOCK))],
        )?;
    }
    tx.execute(
        "CREATE TABLE IF NOT EXISTS schema_version (version BIGINT NOT NULL, applied_at_s BIGINT NOT NULL)",
        &[],
    )?;
    let found = tx
        .query("SELECT MAX(version) FROM schema_version", &[], &[Kind::Int])?
        .first()
        .and_then(|row| row.first().and_then(Value::int))
        .unwrap_or(0);
    if found > latest() {
        return Err(StoreError::NewerSchema {
            location: location.to_owned(),
            found,
            known: latest(),
        });
    }
    for m in MIGRATIONS.iter().filter(|m| m.version > found) {
        for s in m.statements {
            tx.execute(&s.replace("{id}", dialect.id_column()), &[])?;
        }
        tx.execute(
            "INSERT INTO schema_version (version, applied_at_s) VALUES (?, ?)",
            &[Value::Int(Some(m.version)), Value::Int(Some(now_s()))],
        )?;
    }
    Ok(found)
}

/// Now, UTC Unix seconds (0 on a clock before 1970).
pub fn now_s() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX))
}
