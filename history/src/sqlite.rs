//! SQLite: one file, no server. Written ahead (WAL) and synced at each commit, so a writer
//! killed part-way leaves its transaction unapplied and every commit before it in the file;
//! writers of other processes wait for each other (busy timeout) instead of failing.

use crate::backend::{commit_after, Dialect, Kind, Tx, Value};
use crate::error::StoreError;
use rusqlite::types::Value as Sql;
use rusqlite::{Connection, TransactionBehavior};
use std::time::Duration;

/// How long a writer waits for another's transaction before it gives up.
const BUSY: Duration = Duration::from_secs(60);

/// An open SQLite file.
pub struct Sqlite {
    conn: Connection,
    location: String,
}

impl Sqlite {
    pub fn open(path: &str) -> Result<Sqlite, StoreError> {
        let err = |source| StoreError::Sqlite {
            location: path.to_owned(),
            source,
        };
        let conn = Connection::open(path).map_err(err)?;
        conn.busy_timeout(BUSY).map_err(err)?;
        // WAL: readers do not block the writer; FULL: a commit is on disk when it returns
        conn.pragma_update(None, "journal_mode", "WAL")
            .map_err(err)?;
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(err)?;
        conn.pragma_update(None, "foreign_keys", "ON")
            .map_err(err)?;
        Ok(Sqlite {
            conn,
            location: path.to_owned(),
        })
    }

    /// Runs `work` in one transaction that takes the write lock at its start (so two writers
    /// never deadlock upgrading a read), committed when `work` succeeds.
    pub fn transaction<T>(
        &mut self,
        work: impl FnOnce(&mut dyn Tx) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let location = self.location.clone();
        let err = |source| StoreError::Sqlite {
            location: location.clone(),
            source,
        };
        let tx = self
            .conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(err)?;
        let open = SqliteTx {
            tx,
            location: &self.location,
        };
        commit_after(open, work, |o| o.tx.commit().map_err(err))
    }
}

struct SqliteTx<'a> {
    tx: rusqlite::Transaction<'a>,
    location: &'a str,
}

fn bind(params: &[Value]) -> Vec<Sql> {
    params
        .iter()
        .map(|v| match v {
            Value::Int(Some(i)) => Sql::Integer(*i),
            Value::Real(Some(r)) => Sql::Real(*r),
            Value::Text(Some(t)) => Sql::Text(t.clone()),
            Value::Int(None) | Value::Real(None) | Value::Text(None) => Sql::Null,
        })
        .collect()
}

fn read(row: &rusqlite::Row, k: usize, kind: Kind) -> rusqlite::Result<Value> {
    Ok(match kind {
        Kind::Int => Value::Int(row.get(k)?),
        Kind::Real => Value::Real(row.get(k)?),
        Kind::Text => Value::Text(row.get(k)?),
    })
}

impl Tx for SqliteTx<'_> {
    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, StoreError> {
        let n = self
            .tx
            .execute(sql, rusqlite::params_from_iter(bind(params)))
            .map_err(|source| self.error(source))?;
        Ok(n as u64)
    }

    fn query(
        &mut self,
        sql: &str,
        params: &[Value],
        kinds: &[Kind],
    ) -> Result<Vec<Vec<Value>>, StoreError> {
        let mut stmt = self.tx.prepare(sql).map_err(|source| StoreError::Sqlite {
            location: self.location.to_owned(),
            source,
        })?;
        let rows = stmt
            .query_map(rusqlite::params_from_iter(bind(params)), |row| {
                kinds
                    .iter()
                    .enumerate()
                    .map(|(k, &kind)| read(row, k, kind))
                    .collect::<rusqlite::Result<Vec<Value>>>()
            })
            .and_then(Iterator::collect::<rusqlite::Result<Vec<_>>>);
        rows.map_err(|source| StoreError::Sqlite {
            location: self.location.to_owned(),
            source,
        })
    }

    fn dialect(&self) -> Dialect {
        Dialect::Sqlite
    }
}

impl SqliteTx<'_> {
    fn error(&self, source: rusqlite::Error) -> StoreError {
        StoreError::Sqlite {
            location: self.location.to_owned(),
            source,
        }
    }
}
