//! The one interface over both databases: open by location (a path: SQLite; a
//! `postgres://` URL: PostgreSQL), record calibrations and events, each record (or a
//! [`Batch`] of them) one transaction, and read a machine's history back in time order.

use crate::backend::{Kind, Tx, Value};
use crate::error::StoreError;
use crate::pg::Pg;
use crate::record::{CalibrationRecord, CampaignId, EventKind, EventRecord, NoiseLevel, Stored};
use crate::schema;
use crate::sqlite::Sqlite;
use nalgebra::SMatrix;
use rpkm_core::params::{index_of, Model, Params, NAMES, N_PARAMS};
use std::collections::BTreeMap;

enum Db {
    Sqlite(Sqlite),
    Pg(Pg),
}

/// A history store, open.
pub struct Store {
    db: Db,
    location: String,
    notes: Vec<String>,
}

/// Whether `location` names a PostgreSQL database (else an SQLite file).
pub fn is_postgres(location: &str) -> bool {
    location.starts_with("postgres://") || location.starts_with("postgresql://")
}

/// Records written in one transaction ([`Store::batch`]): all of them, or none.
pub struct Batch<'t> {
    tx: &'t mut dyn Tx,
    location: &'t str,
}

impl Store {
    /// Opens the store at `location`: a `postgres://` or `postgresql://` URL (completed from
    /// the process's environment and password file as libpq completes it), else the path
    /// of an SQLite file (made if missing); the schema is migrated to this build's.
    pub fn open(location: &str) -> Result<Store, StoreError> {
        Store::open_with(location, &crate::libpq::process_env)
    }

    /// [`Store::open`] with the environment `env` in place of the process's.
    pub fn open_with(location: &str, env: crate::libpq::Env) -> Result<Store, StoreError> {
        let (db, shown, notes) = if is_postgres(location) {
            let (pg, notes) = Pg::open(location, env)?;
            let shown = pg.location().to_owned();
            (Db::Pg(pg), shown, notes)
        } else {
            (
                Db::Sqlite(Sqlite::open(location)?),
                location.to_owned(),
                Vec::new(),
            )
        };
        let mut store = Store {
            db,
            location: shown,
            notes,
        };
        let at = store.location.clone();
        store.transaction(|tx| schema::migrate(tx, &at))?;
        Ok(store)
    }

    /// What opening it noticed and did not refuse (a password file ignored as unsafe).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Removes calibration `id` with its parameters and noise (a spool's record once it is
    /// in the history it waited for).
    pub fn remove_calibration(&mut self, id: i64) -> Result<(), StoreError> {
        self.transaction(|tx| {
            tx.execute(
                "DELETE FROM parameters WHERE calibration_id = ?",
                &[Value::Int(Some(id))],
            )?;
            tx.execute(
                "DELETE FROM noise WHERE calibration_id = ?",
                &[Value::Int(Some(id))],
            )?;
            tx.execute(
                "DELETE FROM calibrations WHERE id = ?",
                &[Value::Int(Some(id))],
            )?;
            Ok(())
        })
    }

    /// Removes event `id`.
    pub fn remove_event(&mut self, id: i64) -> Result<(), StoreError> {
        self.transaction(|tx| {
            tx.execute("DELETE FROM events WHERE id = ?", &[Value::Int(Some(id))])?;
            Ok(())
        })
    }

    /// Where it is (a URL without its password).
    pub fn location(&self) -> &str {
        &self.location
    }

    fn transaction<T>(
        &mut self,
        work: impl FnOnce(&mut dyn Tx) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        match &mut self.db {
            Db::Sqlite(db) => db.transaction(work),
            Db::Pg(db) => db.transaction(work),
        }
    }

    /// Runs `work` with a [`Batch`] in one transaction, committed when it succeeds: a
    /// calibration and the events of its run land together, or not at all.
    pub fn batch<T>(
        &mut self,
        work: impl FnOnce(&mut Batch) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let location = self.location.clone();
        self.transaction(|tx| {
            work(&mut Batch {
                tx,
                location: &location,
            })
        })
    }

    /// Records a calibration; its id, or None where the same (machine, time, campaign,
    /// source) is already recorded (a retried write records once).
    pub fn record_calibration(
        &mut self,
        record: &CalibrationRecord,
    ) -> Result<Option<i64>, StoreError> {
        self.batch(|b| b.calibration(record))
    }

    /// Records an event; false where the same one is already recorded.
    pub fn record_event(&mut self, event: &EventRecord) -> Result<bool, StoreError> {
        self.batch(|b| b.event(event))
    }

    /// The machines recorded, each with its number of calibrations.
    pub fn machines(&mut self) -> Result<Vec<(String, u64)>, StoreError> {
        let rows = self.transaction(|tx| {
            tx.query(
                "SELECT machine, COUNT(*) FROM calibrations GROUP BY machine ORDER BY machine",
                &[],
                &[Kind::Text, Kind::Int],
            )
        })?;
        Ok(rows
            .iter()
            .map(|r| {
                let n = r[1].int().and_then(|n| u64::try_from(n).ok());
                (r[0].text().unwrap_or_default().to_owned(), n.unwrap_or(0))
            })
            .collect())
    }

    /// The machines with events recorded.
    pub fn event_machines(&mut self) -> Result<Vec<String>, StoreError> {
        let rows = self.transaction(|tx| {
            tx.query(
                "SELECT DISTINCT machine FROM events ORDER BY machine",
                &[],
                &[Kind::Text],
            )
        })?;
        Ok(rows
            .iter()
            .map(|r| r[0].text().unwrap_or_default().to_owned())
            .collect())
    }

    /// A machine's calibrations, oldest first.
    pub fn calibrations(
        &mut self,
        machine: &str,
    ) -> Result<Vec<Stored<CalibrationRecord>>, StoreError> {
        let location = self.location.clone();
        self.transaction(|tx| read_calibrations(tx, machine, &location))
    }

    /// A machine's events, oldest first.
    pub fn events(&mut self, machine: &str) -> Result<Vec<Stored<EventRecord>>, StoreError> {
        let location = self.location.clone();
        self.transaction(|tx| read_events(tx, machine, &location))
    }
}

impl Batch<'_> {
    /// Records a calibration in this batch (see [`Store::record_calibration`]).
    pub fn calibration(&mut self, record: &CalibrationRecord) -> Result<Option<i64>, StoreError> {
        check_calibration(record, self.location)?;
        insert_calibration(self.tx, record, self.location)
    }

    /// Records an event in this batch (see [`Store::record_event`]).
    pub fn event(&mut self, event: &EventRecord) -> Result<bool, StoreError> {
        check_text(
            [&event.machine, &event.source, &event.message],
            self.location,
        )?;
        let n = self.tx.execute(
            "INSERT INTO events (machine, at_s, source, kind, parameter, change, sigma, \
             stream_t_s, message) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT DO NOTHING",
            &[
                text(&event.machine),
                Value::Int(Some(event.at_s)),
                text(&event.source),
                text(event.kind.as_str()),
                Value::Text(event.parameter.clone()),
                finite(event.change),
                finite(event.sigma),
                finite(event.stream_t_s),
                text(&event.message),
            ],
        )?;
        Ok(n > 0)
    }
}

fn text(s: &str) -> Value {
    Value::Text(Some(s.to_owned()))
}

fn real(v: f64) -> Value {
    Value::Real(Some(v))
}

/// A value that is not finite is stored as NULL (unknown), never as a number.
fn finite(v: Option<f64>) -> Value {
    Value::Real(v.filter(|v| v.is_finite()))
}

fn count(n: u64) -> Value {
    Value::Int(Some(i64::try_from(n).unwrap_or(i64::MAX)))
}

/// Texts a database can hold (no NUL: PostgreSQL refuses it).
fn check_text<'a>(
    texts: impl IntoIterator<Item = &'a String>,
    location: &str,
) -> Result<(), StoreError> {
    match texts.into_iter().find(|t| t.contains('\0')) {
        Some(t) => Err(StoreError::BadRecord {
            location: location.to_owned(),
            what: format!("a text with a NUL character: {t:?}"),
        }),
        None => Ok(()),
    }
}

/// A calibration whose numbers are finite and texts storable.
fn check_calibration(r: &CalibrationRecord, location: &str) -> Result<(), StoreError> {
    check_text(
        [&r.machine, &r.source, &r.campaign.name, &r.campaign.digest],
        location,
    )?;
    let bad = (0..N_PARAMS)
        .find(|&i| !(r.params[i].is_finite() && r.tolerance[i] > 0.0))
        .map(|i| {
            format!(
                "{} = {} (tolerance {})",
                NAMES[i], r.params[i], r.tolerance[i]
            )
        })
        .or_else(|| {
            (!r.covariance.iter().all(|v| v.is_finite()))
                .then(|| "a covariance that is not finite".to_owned())
        })
        .or_else(|| (!r.chi2_per_dof.is_finite()).then(|| format!("chi2/dof {}", r.chi2_per_dof)));
    match bad {
        Some(what) => Err(StoreError::BadRecord {
            location: location.to_owned(),
            what,
        }),
        None => Ok(()),
    }
}

/// The covariance as JSON rows in parameter order.
fn covariance_json(c: &SMatrix<f64, N_PARAMS, N_PARAMS>) -> String {
    let rows: Vec<Vec<f64>> = (0..N_PARAMS)
        .map(|i| (0..N_PARAMS).map(|j| c[(i, j)]).collect())
        .collect();
    serde_json::Value::from(rows).to_string()
}

fn insert_calibration(
    tx: &mut dyn Tx,
    r: &CalibrationRecord,
    location: &str,
) -> Result<Option<i64>, StoreError> {
    let (determined, of) = r.determined.unzip();
    let rows = tx.query(
        "INSERT INTO calibrations (machine, at_s, source, campaign, campaign_digest, poses, \
         rows_used, model, effects, determined, determined_of, chi2_per_dof, held_out_rms_um, \
         verdict, covariance) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) \
         ON CONFLICT DO NOTHING RETURNING id",
        &[
            text(&r.machine),
            Value::Int(Some(r.at_s)),
            text(&r.source),
            text(&r.campaign.name),
            text(&r.campaign.digest),
            count(r.campaign.poses),
            count(r.campaign.rows),
            Value::Int(Some(i64::from(r.model.number()))),
            text(&r.effects.to_string()),
            Value::Int(determined.map(|n| i64::try_from(n).unwrap_or(i64::MAX))),
            Value::Int(of.map(|n| i64::try_from(n).unwrap_or(i64::MAX))),
            real(r.chi2_per_dof),
            finite(r.held_out_rms_um),
            Value::Text(r.verdict.clone()),
            text(&covariance_json(&r.covariance)),
        ],
        &[Kind::Int],
    )?;
    let Some(id) = rows.first().and_then(|row| row[0].int()) else {
        return Ok(None);
    };
    for i in r.model.params() {
        tx.execute(
            "INSERT INTO parameters (calibration_id, name, value, sigma, tolerance) \
             VALUES (?, ?, ?, ?, ?)",
            &[
                Value::Int(Some(id)),
                text(NAMES[i]),
                real(r.params[i]),
                real(r.covariance[(i, i)].max(0.0).sqrt()),
                real(r.tolerance[i]),
            ],
        )?;
    }
    for g in &r.noise {
        check_text([&g.group, &g.unit], location)?;
        tx.execute(
            "INSERT INTO noise (calibration_id, noise_group, unit, stated, estimated, dof) \
             VALUES (?, ?, ?, ?, ?, ?)",
            &[
                Value::Int(Some(id)),
                text(&g.group),
                text(&g.unit),
                real(g.stated),
                real(g.estimated),
                real(g.dof),
            ],
        )?;
    }
    Ok(Some(id))
}

/// Columns of a calibration row, in [`CALIBRATION_COLUMNS`] order.
const CALIBRATION_KINDS: [Kind; 15] = [
    Kind::Int,
    Kind::Int,
    Kind::Text,
    Kind::Text,
    Kind::Text,
    Kind::Int,
    Kind::Int,
    Kind::Int,
    Kind::Text,
    Kind::Int,
    Kind::Int,
    Kind::Real,
    Kind::Real,
    Kind::Text,
    Kind::Text,
];
const CALIBRATION_COLUMNS: &str = "id, at_s, source, campaign, campaign_digest, poses, \
    rows_used, model, effects, determined, determined_of, chi2_per_dof, held_out_rms_um, \
    verdict, covariance";

/// A stored row that does not read as it should.
fn corrupt(location: &str, id: i64, what: impl Into<String>) -> StoreError {
    StoreError::Corrupt {
        location: location.to_owned(),
        id,
        what: what.into(),
    }
}

fn read_calibrations(
    tx: &mut dyn Tx,
    machine: &str,
    location: &str,
) -> Result<Vec<Stored<CalibrationRecord>>, StoreError> {
    let rows = tx.query(
        &format!(
            "SELECT {CALIBRATION_COLUMNS} FROM calibrations WHERE machine = ? ORDER BY at_s, id"
        ),
        &[text(machine)],
        &CALIBRATION_KINDS,
    )?;
    let mut params = read_parameters(tx, machine)?;
    let mut noise = read_noise(tx, machine)?;
    rows.iter()
        .map(|row| {
            let id = row[0].int().unwrap_or_default();
            let mut record = calibration_of(row, machine, location)?;
            let (values, tolerance) = params
                .remove(&id)
                .ok_or_else(|| corrupt(location, id, "no parameters"))?;
            record.params = values;
            record.tolerance = tolerance;
            record.noise = noise.remove(&id).unwrap_or_default();
            Ok(Stored { id, record })
        })
        .collect()
}

/// A calibration row (without its parameters and noise, read apart).
fn calibration_of(
    row: &[Value],
    machine: &str,
    location: &str,
) -> Result<CalibrationRecord, StoreError> {
    let id = row[0].int().unwrap_or_default();
    let bad = |what: &str| corrupt(location, id, what);
    let model = row[7]
        .int()
        .and_then(|n| u32::try_from(n).ok())
        .and_then(Model::from_number)
        .ok_or_else(|| bad("model is not 24 or 29"))?;
    let effects: serde_json::Value = serde_json::from_str(row[8].text().unwrap_or_default())
        .map_err(|e| bad(&format!("effects: {e}")))?;
    let cov: Vec<Vec<f64>> = serde_json::from_str(row[14].text().unwrap_or_default())
        .map_err(|e| bad(&format!("covariance: {e}")))?;
    if cov.len() != N_PARAMS || cov.iter().any(|r| r.len() != N_PARAMS) {
        return Err(bad("covariance is not 29 x 29"));
    }
    let unsigned = |v: &Value| v.int().and_then(|n| u64::try_from(n).ok());
    Ok(CalibrationRecord {
        machine: machine.to_owned(),
        at_s: row[1].int().unwrap_or_default(),
        source: row[2].text().unwrap_or_default().to_owned(),
        campaign: CampaignId {
            name: row[3].text().unwrap_or_default().to_owned(),
            digest: row[4].text().unwrap_or_default().to_owned(),
            poses: unsigned(&row[5]).unwrap_or(0),
            rows: unsigned(&row[6]).unwrap_or(0),
        },
        model,
        effects,
        params: Params::nominal(),
        covariance: SMatrix::from_fn(|i, j| cov[i][j]),
        tolerance: [0.0; N_PARAMS],
        determined: unsigned(&row[9]).zip(unsigned(&row[10])),
        noise: Vec::new(),
        chi2_per_dof: row[11].real().unwrap_or(f64::NAN),
        held_out_rms_um: row[12].real(),
        verdict: row[13].text().map(str::to_owned),
    })
}

/// The parameters of a machine's calibrations by calibration id: values (nominal where a
/// model has none) and tolerances.
fn read_parameters(
    tx: &mut dyn Tx,
    machine: &str,
) -> Result<BTreeMap<i64, (Params, [f64; N_PARAMS])>, StoreError> {
    let rows = tx.query(
        "SELECT p.calibration_id, p.name, p.value, p.tolerance FROM parameters p \
         JOIN calibrations c ON c.id = p.calibration_id WHERE c.machine = ?",
        &[text(machine)],
        &[Kind::Int, Kind::Text, Kind::Real, Kind::Real],
    )?;
    let mut out: BTreeMap<i64, (Params, [f64; N_PARAMS])> = BTreeMap::new();
    for row in rows {
        let (Some(id), Some(i)) = (row[0].int(), row[1].text().and_then(index_of)) else {
            continue;
        };
        let entry = out.entry(id).or_insert_with(|| {
            let prior = rpkm_core::calib::Prior::default();
            (Params::nominal(), std::array::from_fn(|k| prior.sigma(k)))
        });
        entry.0[i] = row[2].real().unwrap_or(f64::NAN);
        entry.1[i] = row[3].real().unwrap_or(f64::NAN);
    }
    Ok(out)
}

fn read_noise(
    tx: &mut dyn Tx,
    machine: &str,
) -> Result<BTreeMap<i64, Vec<NoiseLevel>>, StoreError> {
    let rows = tx.query(
        "SELECT n.calibration_id, n.noise_group, n.unit, n.stated, n.estimated, n.dof \
         FROM noise n JOIN calibrations c ON c.id = n.calibration_id WHERE c.machine = ? \
         ORDER BY n.calibration_id, n.noise_group",
        &[text(machine)],
        &[
            Kind::Int,
            Kind::Text,
            Kind::Text,
            Kind::Real,
            Kind::Real,
            Kind::Real,
        ],
    )?;
    let mut out: BTreeMap<i64, Vec<NoiseLevel>> = BTreeMap::new();
    for row in rows {
        out.entry(row[0].int().unwrap_or_default())
            .or_default()
            .push(NoiseLevel {
                group: row[1].text().unwrap_or_default().to_owned(),
                unit: row[2].text().unwrap_or_default().to_owned(),
                stated: row[3].real().unwrap_or(f64::NAN),
                estimated: row[4].real().unwrap_or(f64::NAN),
                dof: row[5].real().unwrap_or(f64::NAN),
            });
    }
    Ok(out)
}

fn read_events(
    tx: &mut dyn Tx,
    machine: &str,
    location: &str,
) -> Result<Vec<Stored<EventRecord>>, StoreError> {
    let rows = tx.query(
        "SELECT id, at_s, source, kind, parameter, change, sigma, stream_t_s, message \
         FROM events WHERE machine = ? ORDER BY at_s, id",
        &[text(machine)],
        &[
            Kind::Int,
            Kind::Int,
            Kind::Text,
            Kind::Text,
            Kind::Text,
            Kind::Real,
            Kind::Real,
            Kind::Real,
            Kind::Text,
        ],
    )?;
    rows.iter()
        .map(|r| {
            let id = r[0].int().unwrap_or_default();
            let stored = r[3].text().unwrap_or_default();
            let kind = EventKind::parse(stored).ok_or_else(|| StoreError::UnknownEventKind {
                location: location.to_owned(),
                id,
                kind: stored.to_owned(),
            })?;
            Ok(Stored {
                id,
                record: EventRecord {
                    machine: machine.to_owned(),
                    at_s: r[1].int().unwrap_or_default(),
                    source: r[2].text().unwrap_or_default().to_owned(),
                    kind,
                    parameter: r[4].text().map(str::to_owned),
                    change: r[5].real(),
                    sigma: r[6].real(),
                    stream_t_s: r[7].real(),
                    message: r[8].text().unwrap_or_default().to_owned(),
                },
            })
        })
        .collect()
}
