//! A writer that outlives its server: records go to the history when it can be reached,
//! and otherwise wait in a spool (an SQLite file of the same schema, synced at each commit,
//! so that a record waits through a restart of the writer too), bounded in size; the server
//! is tried again with a doubling wait, and at every new record, and the spool is emptied
//! into it, oldest first, as soon as it answers. Only a server away makes a record wait:
//! settings the server refuses are an error at once, and a record the history refuses is
//! said as failed, never queued to fail again.

use crate::error::{StoreError, StoreFault};
use crate::record::{CalibrationRecord, EventRecord};
use crate::store::{is_postgres, Store};
use std::path::Path;
use std::time::{Duration, Instant};

/// The longest wait between two tries of a server away.
pub const MAX_RETRY: Duration = Duration::from_secs(60);

/// What became of a record.
#[derive(Debug)]
pub enum RecordOutcome<T> {
    /// In the history: as the store said it (a calibration's id, None where it already
    /// was; whether an event was new).
    Recorded(T),
    /// In the spool: how many records wait now, and why.
    Queued { waiting: usize, why: String },
    /// Neither: why.
    Failed(String),
}

/// What a retry did.
#[derive(Debug, PartialEq, Eq)]
pub enum Retried {
    /// The server answers again: records moved from the spool into the history, and those
    /// it refused (each said; taken out of the spool, as they would be refused again).
    Reconnected {
        flushed: usize,
        refused: Vec<String>,
    },
    /// Still away (said once per outage, when it began or the reason changed).
    StillAway(String),
}

/// The history's writer.
pub struct Writer {
    /// The location as given (a URL may hold a password: never shown).
    location: String,
    store: Option<Store>,
    spool: Option<Store>,
    capacity: usize,
    first_retry: Duration,
    retry: Duration,
    next_try: Instant,
    /// Why the server is away, while it is.
    away: Option<String>,
    /// Records waiting in the spool.
    queued: usize,
}

impl Writer {
    /// Opens the history at `location`. A PostgreSQL server away is no error: the writer
    /// starts without it and queues in the spool file `spool` (at most `capacity` records),
    /// trying it again after `first_retry`, doubling to [`MAX_RETRY`]. An SQLite file has
    /// no spool: it is here or it is an error.
    pub fn open(
        location: &str,
        spool: &Path,
        capacity: usize,
        first_retry: Duration,
    ) -> Result<Writer, StoreError> {
        let mut w = Writer {
            location: location.to_owned(),
            store: None,
            spool: None,
            capacity,
            first_retry,
            retry: first_retry,
            next_try: Instant::now(),
            away: None,
            queued: 0,
        };
        if !is_postgres(location) {
            w.store = Some(Store::open(location)?);
            return Ok(w);
        }
        if let Some(dir) = spool.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| StoreError::Config {
                location: spool.display().to_string(),
                what: format!("the spool's directory: {e}"),
            })?;
        }
        let mut sp = Store::open(&spool.to_string_lossy())?;
        w.queued = count(&mut sp)?;
        w.spool = Some(sp);
        w.connect()?;
        Ok(w)
    }

    /// The history, when it is connected.
    pub fn store(&mut self) -> Option<&mut Store> {
        self.store.as_mut()
    }

    /// Why the server is away, while it is.
    pub fn away(&self) -> Option<&str> {
        self.away.as_deref()
    }

    /// Records waiting in the spool.
    pub fn waiting(&self) -> usize {
        self.queued
    }

    /// Where the records go, and where they wait.
    pub fn describe(&self) -> String {
        match (&self.store, &self.spool) {
            (Some(s), None) => s.location().to_owned(),
            (Some(s), Some(sp)) => format!("{} (spool {})", s.location(), sp.location()),
            (None, Some(sp)) => format!(
                "{} (away: {}; spool {})",
                crate::pg::without_password(&self.location),
                self.away.as_deref().unwrap_or_default(),
                sp.location()
            ),
            (None, None) => crate::pg::without_password(&self.location),
        }
    }

    /// Tries the server: a configuration fault is an error; a server away is noted (and
    /// the next try set); otherwise the history is open.
    fn connect(&mut self) -> Result<(), StoreError> {
        match Store::open(&self.location) {
            Ok(s) => {
                self.store = Some(s);
                self.away = None;
                self.retry = self.first_retry;
                Ok(())
            }
            Err(e) if e.fault() == StoreFault::Unreachable => {
                self.went_away(&e);
                Ok(())
            }
            Err(e) => Err(e),
        }
    }

    fn went_away(&mut self, e: &StoreError) {
        self.store = None;
        self.away = Some(crate::error::chain(e));
        self.next_try = Instant::now() + self.retry;
        self.retry = (self.retry * 2).min(MAX_RETRY);
    }

    /// When due (or `now_anyway`, at a new record), tries a server away again and empties
    /// the spool into it; what happened, where something did.
    pub fn retry(&mut self, now_anyway: bool) -> Result<Option<Retried>, StoreError> {
        let due = now_anyway || Instant::now() >= self.next_try;
        if self.spool.is_none() || !due || (self.store.is_some() && self.queued == 0) {
            return Ok(None);
        }
        let was = self.away.clone();
        if self.store.is_none() {
            self.connect()?;
        }
        if self.store.is_some() {
            let (flushed, refused) = self.flush()?;
            if self.store.is_some() {
                return Ok(Some(Retried::Reconnected { flushed, refused }));
            }
        }
        Ok(match &self.away {
            Some(why) if was.as_ref() != Some(why) => Some(Retried::StillAway(why.clone())),
            _ => None,
        })
    }

    /// Moves the spool's records into the history, oldest first: how many, and the ones it
    /// refused. A server that goes away meanwhile leaves the rest waiting; settings it now
    /// refuses are an error (the records stay).
    fn flush(&mut self) -> Result<(usize, Vec<String>), StoreError> {
        let (Some(spool), Some(store)) = (self.spool.as_mut(), self.store.as_mut()) else {
            return Ok((0, Vec::new()));
        };
        let (mut moved, mut refused) = (0, Vec::new());
        let mut lost = None;
        'calibrations: for (machine, _) in spool.machines()? {
            for c in spool.calibrations(&machine)? {
                match settle(store.record_calibration(&c.record).map(|_| ()))? {
                    Settled::Lost(e) => {
                        lost = Some(e);
                        break 'calibrations;
                    }
                    Settled::Refused(why) => refused.push(format!(
                        "the calibration of {machine} at {} s: {why}",
                        c.record.at_s
                    )),
                    Settled::Written => moved += 1,
                }
                spool.remove_calibration(c.id)?;
                self.queued = self.queued.saturating_sub(1);
            }
        }
        'events: for machine in spool.event_machines()? {
            if lost.is_some() {
                break;
            }
            for ev in spool.events(&machine)? {
                match settle(store.record_event(&ev.record).map(|_| ()))? {
                    Settled::Lost(e) => {
                        lost = Some(e);
                        break 'events;
                    }
                    Settled::Refused(why) => refused.push(format!(
                        "the event of {machine} at {} s: {why}",
                        ev.record.at_s
                    )),
                    Settled::Written => moved += 1,
                }
                spool.remove_event(ev.id)?;
                self.queued = self.queued.saturating_sub(1);
            }
        }
        if let Some(e) = lost {
            self.went_away(&e);
        }
        Ok((moved, refused))
    }

    /// Records a calibration: in the history (its id, None where it already was), or
    /// waiting in the spool.
    pub fn calibration(&mut self, r: &CalibrationRecord) -> RecordOutcome<Option<i64>> {
        self.write(
            |s| s.record_calibration(r),
            |sp| sp.record_calibration(r).map(|_| ()),
        )
    }

    /// Records an event: in the history (whether it was new), or waiting in the spool.
    pub fn event(&mut self, e: &EventRecord) -> RecordOutcome<bool> {
        self.write(|s| s.record_event(e), |sp| sp.record_event(e).map(|_| ()))
    }

    /// Writes to the history, reconnecting once where the connection was lost (a server
    /// restarted since the last record); else queues.
    fn write<T>(
        &mut self,
        direct: impl Fn(&mut Store) -> Result<T, StoreError>,
        queue: impl FnOnce(&mut Store) -> Result<(), StoreError>,
    ) -> RecordOutcome<T> {
        // the records waiting go first, and a server away is tried once more now; settings
        // it now refuses (a password changed) make the record wait too, and the next retry
        // says it as the error it is
        let mut refused = match self.retry(true) {
            Ok(_) => None,
            Err(e) if e.fault() == StoreFault::Configuration => Some(crate::error::chain(&e)),
            Err(e) => return RecordOutcome::Failed(crate::error::chain(&e)),
        };
        for attempt in 0..2 {
            let Some(store) = self.store.as_mut().filter(|_| refused.is_none()) else {
                break;
            };
            match direct(store) {
                Ok(v) => return RecordOutcome::Recorded(v),
                Err(e) if e.fault() == StoreFault::Unreachable && self.spool.is_some() => {
                    self.went_away(&e);
                    if attempt == 0 {
                        match self.connect() {
                            Ok(()) => {}
                            Err(e) if e.fault() == StoreFault::Configuration => {
                                refused = Some(crate::error::chain(&e));
                            }
                            Err(e) => return RecordOutcome::Failed(crate::error::chain(&e)),
                        }
                    }
                }
                Err(e) => return RecordOutcome::Failed(crate::error::chain(&e)),
            }
        }
        let why = refused.or_else(|| self.away.clone()).unwrap_or_default();
        if self.queued >= self.capacity {
            return RecordOutcome::Failed(format!(
                "{why}; the spool is full ({} records waiting)",
                self.queued
            ));
        }
        let Some(spool) = self.spool.as_mut() else {
            return RecordOutcome::Failed(why);
        };
        match queue(spool) {
            Ok(()) => {
                self.queued += 1;
                RecordOutcome::Queued {
                    waiting: self.queued,
                    why,
                }
            }
            Err(e) => {
                RecordOutcome::Failed(format!("{why}; the spool: {}", crate::error::chain(&e)))
            }
        }
    }
}

/// Records in a spool: its calibrations and events.
fn count(s: &mut Store) -> Result<usize, StoreError> {
    let calibrations: u64 = s.machines()?.iter().map(|(_, n)| n).sum();
    let mut events = 0;
    for m in s.event_machines()? {
        events += s.events(&m)?.len();
    }
    Ok(usize::try_from(calibrations).unwrap_or(usize::MAX) + events)
}

/// What became of a waiting record offered to the history.
enum Settled {
    Written,
    /// The server went away: it waits on.
    Lost(StoreError),
    /// The history refuses it (why): it would be refused again.
    Refused(String),
}

/// A waiting record's write settled; settings the server refuses are an error.
fn settle(r: Result<(), StoreError>) -> Result<Settled, StoreError> {
    match r {
        Ok(()) => Ok(Settled::Written),
        Err(e) => match e.fault() {
            StoreFault::Unreachable => Ok(Settled::Lost(e)),
            StoreFault::Configuration => Err(e),
            StoreFault::Other => Ok(Settled::Refused(crate::error::chain(&e))),
        },
    }
}
