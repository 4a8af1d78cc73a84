//! rpkm-history: a machine's history kept in a database. Every calibration of a machine is
//! recorded with what makes it comparable with the next (its campaign's digest and size, the
//! model, the effects, the parameters with their covariance and tolerances, the noise the
//! campaign showed, the held-out RMS, the verdict), and the online tracker's steps and
//! settled ties as events; the core's `history` then says what changed and how it trends.
//!
//! One interface, [`Store`], over two databases with one schema and its migrations
//! ([`schema`]): SQLite, one file and no server (`machine.db`, the default), and PostgreSQL, a
//! plant's database that many cells write to at once (`postgres://user@host/db`). Each record
//! is one transaction: a writer killed part-way leaves nothing of its record, and everything
//! committed before it intact.
//!
//! A PostgreSQL URL is completed as libpq completes it ([`libpq`]: the plant's `PGPASSWORD`,
//! password file, service file), and [`Writer`] keeps records through a server's absence
//! (a spool file, retries); a failure says what it asks for ([`StoreFault`]).

mod backend;
mod error;
pub mod libpq;
mod pg;
mod record;
pub mod schema;
mod sqlite;
mod store;
mod writer;

pub use error::{StoreError, StoreFault};
pub use record::{CalibrationRecord, CampaignId, EventKind, EventRecord, NoiseLevel, Stored};
pub use store::{is_postgres, Batch, Store};
pub use writer::{RecordOutcome, Retried, Writer, MAX_RETRY};

#[cfg(test)]
mod tests;
