//! PostgreSQL: a plant's database that many cells write to at once, through the synchronous
//! client. Each record is one transaction; the schema's migrations take an advisory lock so
//! that two writers starting on an empty database migrate it once.

use crate::backend::{commit_after, numbered, Dialect, Kind, Tx, Value};
use crate::error::StoreError;
use crate::error::StoreFault;
use crate::libpq::{resolve, Env, Resolved};
use postgres::types::ToSql;
use postgres::{Client, NoTls};

/// A connection that failed: a configuration fault says what to change (and the password
/// file ignored, if one was), anything else as the client said it.
fn connect_error(source: postgres::Error, shown: &str, notes: &[String]) -> StoreError {
    if crate::error::postgres_fault(&source) == StoreFault::Configuration {
        let said = source.to_string();
        let hint = if said.contains("password missing") {
            "; give it in PGPASSWORD, a line of the password file (PGPASSFILE, else \
             ~/.pgpass) or the URL"
        } else {
            ""
        };
        let mut what = format!("{}{hint}", crate::error::chain(&source));
        for n in notes {
            what.push_str("; ");
            what.push_str(n);
        }
        return StoreError::Config {
            location: shown.to_owned(),
            what,
        };
    }
    StoreError::Postgres {
        location: shown.to_owned(),
        source,
    }
}

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
    /// Connects to `url` completed as libpq completes it ([`crate::libpq`]) from `env`;
    /// also what the completion noticed (a password file ignored).
    pub fn open(url: &str, env: Env) -> Result<(Pg, Vec<String>), StoreError> {
        let Resolved {
            config,
            shown,
            notes,
        } = resolve(url, env)?;
        let client = config
            .connect(NoTls)
            .map_err(|source| connect_error(source, &shown, &notes))?;
        Ok((
            Pg {
                client,
                location: shown,
            },
            notes,
        ))
    }

    /// Where it is: `postgres://user@host:port/database`.
    pub fn location(&self) -> &str {
        &self.location
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
