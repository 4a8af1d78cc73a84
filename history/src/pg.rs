//! PostgreSQL: a plant's database that many cells write to at once, through the synchronous
//! client. Each record is one transaction; the schema's migrations take an advisory lock so
//! that two writers starting on an empty database migrate it once.

use crate::backend::{commit_after, numbered, Dialect, Kind, Tx, Value};
use crate::error::StoreError;
use postgres::types::ToSql;
use postgres::{Client, NoTls};

/// A connection to a PostgreSQL database.
pub struct Pg {
    client: Client,
    /// The URL without its password, for messages.
    location: String,
}

/// `url` with the password of its user part replaced by `***`.
pub fn without_password(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_owned();
    };
    let Some((user, host)) = rest.split_once('@') else {
        return url.to_owned();
    };
    match user.split_once(':') {
        Some((name, _)) => format!("{scheme}://{name}:***@{host}"),
        None => url.to_owned(),
    }
}

impl Pg {
    pub fn open(url: &str) -> Result<Pg, StoreError> {
        let location = without_password(url);
        let client = Client::connect(url, NoTls).map_err(|source| StoreError::Postgres {
            location: location.clone(),
            source,
        })?;
        Ok(Pg { client, location })
    }

    /// Runs `work` in one transaction, committed when it succeeds.
    pub fn transaction<T>(
        &mut self,
        work: impl FnOnce(&mut dyn Tx) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let location = self.location.clone();
        let err = |source| StoreError::Postgres {
            location: location.clone(),
            source,
        };
        let tx = self.client.transaction().map_err(err)?;
        let open = PgTx {
            tx,
            location: &self.location,
        };
        commit_after(open, work, |o| o.tx.commit().map_err(err))
    }
}

struct PgTx<'a> {
    tx: postgres::Transaction<'a>,
    location: &'a str,
}

fn bind(params: &[Value]) -> Vec<Box<dyn ToSql + Sync>> {
    params
        .iter()
        .map(|v| -> Box<dyn ToSql + Sync> {
            match v {
                Value::Int(i) => Box::new(*i),
                Value::Real(r) => Box::new(*r),
                Value::Text(t) => Box::new(t.clone()),
            }
        })
        .collect()
}

fn read(row: &postgres::Row, k: usize, kind: Kind) -> Result<Value, postgres::Error> {
    Ok(match kind {
        Kind::Int => Value::Int(row.try_get(k)?),
        Kind::Real => Value::Real(row.try_get(k)?),
        Kind::Text => Value::Text(row.try_get(k)?),
    })
}

impl Tx for PgTx<'_> {
    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, StoreError> {
        let owned = bind(params);
        let refs: Vec<&(dyn ToSql + Sync)> = owned.iter().map(AsRef::as_ref).collect();
        self.tx
            .execute(numbered(sql).as_str(), &refs)
            .map_err(|source| self.error(source))
    }

    fn query(
        &mut self,
        sql: &str,
        params: &[Value],
        kinds: &[Kind],
    ) -> Result<Vec<Vec<Value>>, StoreError> {
        let owned = bind(params);
        let refs: Vec<&(dyn ToSql + Sync)> = owned.iter().map(AsRef::as_ref).collect();
        let rows = self
            .tx
            .query(numbered(sql).as_str(), &refs)
            .map_err(|source| self.error(source))?;
        rows.iter()
            .map(|row| {
                kinds
                    .iter()
                    .enumerate()
                    .map(|(k, &kind)| read(row, k, kind))
                    .collect::<Result<Vec<Value>, _>>()
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(|source| self.error(source))
    }

    fn dialect(&self) -> Dialect {
        Dialect::Postgres
    }
}

impl PgTx<'_> {
    fn error(&self, source: postgres::Error) -> StoreError {
        StoreError::Postgres {
            location: self.location.to_owned(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_password_never_reaches_a_message() {
        assert_eq!(
            super::without_password("postgres://rpkm:secret@plant-db:5432/history"),
            "postgres://rpkm:***@plant-db:5432/history"
        );
        assert_eq!(
            super::without_password("postgres://rpkm@localhost/h"),
            "postgres://rpkm@localhost/h"
        );
    }
}
