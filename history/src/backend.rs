//! What the store asks of a database: statements and queries inside one transaction, with
//! values of three kinds. SQLite and PostgreSQL each implement it (`sqlite.rs`, `pg.rs`);
//! the SQL is written once with `?` placeholders (PostgreSQL's `$n` made from them).

use crate::error::StoreError;

/// A value bound to or read from a statement; `None` is SQL NULL of that kind.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Int(Option<i64>),
    Real(Option<f64>),
    Text(Option<String>),
}

/// The kind of a column read back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Int,
    Real,
    Text,
}

impl Value {
    pub fn int(&self) -> Option<i64> {
        match self {
            Value::Int(v) => *v,
            _ => None,
        }
    }

    pub fn real(&self) -> Option<f64> {
        match self {
            Value::Real(v) => *v,
            _ => None,
        }
    }

    pub fn text(&self) -> Option<&str> {
        match self {
            Value::Text(v) => v.as_deref(),
            _ => None,
        }
    }
}

/// One transaction of a database.
pub trait Tx {
    /// Runs a statement; the rows it changed.
    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, StoreError>;
    /// Runs a query; each row's columns read as `kinds` say.
    fn query(
        &mut self,
        sql: &str,
        params: &[Value],
        kinds: &[Kind],
    ) -> Result<Vec<Vec<Value>>, StoreError>;
    /// Which database this is: where their SQL differs.
    fn dialect(&self) -> Dialect;
}

/// The two databases' SQL where it differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    Sqlite,
    Postgres,
}

impl Dialect {
    /// An auto-numbered key column.
    pub fn id_column(self) -> &'static str {
        match self {
            Dialect::Sqlite => "INTEGER PRIMARY KEY AUTOINCREMENT",
            Dialect::Postgres => "BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
        }
    }
}

/// Runs `work` in the transaction `open` and commits it with `commit` when `work` succeeds
/// (dropped uncommitted, it rolls back).
pub fn commit_after<X: Tx, T>(
    mut open: X,
    work: impl FnOnce(&mut dyn Tx) -> Result<T, StoreError>,
    commit: impl FnOnce(X) -> Result<(), StoreError>,
) -> Result<T, StoreError> {
    let out = work(&mut open)?;
    commit(open)?;
    Ok(out)
}

/// `sql` with its `?` placeholders numbered `$1, $2, ...` (PostgreSQL's spelling). The
/// statements are ours: no `?` stands inside a string literal.
pub fn numbered(sql: &str) -> String {
    let mut out = String::with_capacity(sql.len() + 16);
    let mut n = 0;
    for c in sql.chars() {
        if c == '?' {
            n += 1;
            out.push('$');
            out.push_str(&n.to_string());
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn placeholders_are_numbered_in_order() {
        assert_eq!(
            super::numbered("INSERT INTO t (a, b) VALUES (?, ?) RETURNING id"),
            "INSERT INTO t (a, b) VALUES ($1, $2) RETURNING id"
        );
    }
}
