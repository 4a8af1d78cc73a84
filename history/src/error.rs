//! What can go wrong with a history store, each naming the store.

/// A history store that cannot be opened, read or written.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{location}: {source}")]
    Sqlite {
        location: String,
        #[source]
        source: rusqlite::Error,
    },
    #[error("{location}: {source}")]
    Postgres {
        location: String,
        #[source]
        source: postgres::Error,
    },
    /// Written by a newer rpkm: its schema has migrations this one does not know.
    #[error("{location}: history schema version {found}, this rpkm knows up to {known}: use a newer rpkm")]
    NewerSchema {
        location: String,
        found: i64,
        known: i64,
    },
    /// A stored value that does not read back as what it should be.
    #[error("{location}: calibration {id}: {what}")]
    Corrupt {
        location: String,
        id: i64,
        what: String,
    },
    /// A record that cannot be stored as it is (a name with a NUL, a non-finite value).
    #[error("{location}: cannot record: {what}")]
    BadRecord { location: String, what: String },
}
