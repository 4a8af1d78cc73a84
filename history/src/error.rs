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
    /// A stored event of a kind this rpkm does not know.
    #[error("{location}: event {id}: kind {kind:?}, expected step or tie_settled")]
    UnknownEventKind {
        location: String,
        id: i64,
        kind: String,
    },
    /// A record that cannot be stored as it is (a name with a NUL, a non-finite value).
    #[error("{location}: cannot record: {what}")]
    BadRecord { location: String, what: String },
    /// Settings that cannot lead to the database: a bad URL, a password missing or refused,
    /// a user or database the server does not know. Retrying does not help; the user must
    /// change them.
    #[error("{location}: {what}")]
    Config { location: String, what: String },
}

/// What a failure of the store asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreFault {
    /// The settings are wrong: retrying does not help.
    Configuration,
    /// The server cannot be reached or went away (refused, closed, shutting down, starting
    /// up, too many connections): the same write may succeed later.
    Unreachable,
    /// Anything else (a record refused, a corrupt store).
    Other,
}

impl StoreError {
    /// What this failure asks for.
    pub fn fault(&self) -> StoreFault {
        match self {
            StoreError::Config { .. } => StoreFault::Configuration,
            StoreError::Postgres { source, .. } => postgres_fault(source),
            _ => StoreFault::Other,
        }
    }
}

/// PostgreSQL's SQLSTATE classes and codes: 28 (authorization: a bad password, a role or
/// address refused) and 3D000 (no such database) are configuration; 08 (connection), 57P01..3
/// (shut down, crashed, starting up) and 53300 (too many connections) are a server away.
pub(crate) fn postgres_fault(e: &postgres::Error) -> StoreFault {
    if let Some(code) = e.code().map(postgres::error::SqlState::code) {
        return if code.starts_with("28") || code == "3D000" {
            StoreFault::Configuration
        } else if code.starts_with("08") || code.starts_with("57P") || code == "53300" {
            StoreFault::Unreachable
        } else {
            StoreFault::Other
        };
    }
    // The client's own error kinds are not public; their words are its Display.
    let said = e.to_string();
    if e.is_closed()
        || said.starts_with("error connecting")
        || said.starts_with("error communicating")
        || said.starts_with("timeout")
    {
        StoreFault::Unreachable
    } else if said.starts_with("invalid configuration")
        || said.starts_with("invalid connection string")
        || said.starts_with("authentication error")
    {
        StoreFault::Configuration
    } else {
        StoreFault::Other
    }
}

/// An error and its causes joined by ": " (the client's "db error" says its cause apart).
pub(crate) fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let line = c.to_string();
        if !text.contains(&line) {
            text.push_str(": ");
            text.push_str(&line);
        }
        cause = c.source();
    }
    text
}
