//! The calibrator's record of its machine (parameter `history`: an SQLite file or a
//! PostgreSQL URL, completed from the plant's libpq environment and password file;
//! `history_machine`: the machine's name, the node's namespace by default): each calibration
//! is recorded, with what changed since the previous calibration of this machine in the
//! history said on /diagnostics, and each step the online tracker names or tie it settles is
//! recorded as an event. A PostgreSQL server away (stopped, restarted, not up yet) loses
//! nothing: records wait in a spool file (`history_spool`, at most `history_spool_max`) and
//! go in once it answers, tried again from `history_retry_s` doubling to a minute; what
//! became of each record (recorded, queued with how many waiting, or not recorded and why)
//! is said on /diagnostics and in a Calibrate goal's result.

use super::online_tracker::{state_name, OnlineReport};
use crate::history::{record_of, words, Made};
use rpkm_core::calib::{Calibration, Prior, Selection};
use rpkm_core::campaign::Campaign;
use rpkm_core::variance::NoiseEstimate;
use rpkm_history::{CalibrationRecord, EventKind, EventRecord, RecordOutcome, Retried, Writer};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A calibration of the node, as the history records it.
pub struct Calibrated<'a> {
    /// The campaign calibrated (without its held-out part).
    pub campaign: &'a Campaign,
    pub calibration: &'a Calibration,
    pub noise: &'a NoiseEstimate,
    /// TCP RMS on the held-out setups, m (NaN without any: the Parameters message's).
    pub val_rms_m: f64,
    /// The diagnosis's verdict in words.
    pub verdict: Option<&'a str>,
}

/// The machine's name when `history_machine` is empty: the node's namespace (`machine_a` for
/// `/machine_a/calibrator`), `rpkm` without one.
pub fn default_machine(status_name: &str, node: &str) -> String {
    let ns = status_name
        .strip_suffix(node)
        .unwrap_or(status_name)
        .trim_matches('/');
    if ns.is_empty() {
        "rpkm".to_owned()
    } else {
        ns.replace('/', "_")
    }
}

/// Where the node's history is and how it waits for a server away (the parameters).
pub struct HistorySettings {
    /// An SQLite file or a `postgres://` URL.
    pub location: String,
    pub machine: String,
    /// The node's status name: who recorded.
    pub source: String,
    /// Where records wait while a server is away.
    pub spool: PathBuf,
    pub spool_max: usize,
    pub first_retry: Duration,
}

/// The spool of `machine` where `history_spool` is empty: `$XDG_STATE_HOME/rpkm`, else
/// `~/.local/state/rpkm`, else the working directory.
pub fn default_spool(machine: &str) -> PathBuf {
    let dir = std::env::var_os("XDG_STATE_HOME")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|d| !d.is_empty())
                .map(|h| Path::new(&h).join(".local/state"))
        })
        .map(|d| d.join("rpkm"))
        .unwrap_or_default();
    dir.join(format!("history-spool-{}.db", machine.replace('/', "_")))
}

/// What the history said of a record or of its server: whether all is well, and the words.
pub struct Said {
    pub ok: bool,
    pub text: String,
}

/// The open history of the node's machine.
pub struct NodeHistory {
    writer: Writer,
    machine: String,
    /// The node's status name: who recorded.
    source: String,
    /// The last calibration of this machine in the history (another cell's included), once
    /// the history has been reached.
    previous: Option<CalibrationRecord>,
    previous_read: bool,
}

impl NodeHistory {
    /// Opens (and migrates) the history of `s`; a PostgreSQL server away is no error (the
    /// records wait), settings it refuses are. Also what opening noticed, to be logged.
    pub fn open(s: &HistorySettings) -> anyhow::Result<(NodeHistory, Vec<String>)> {
        let mut writer = Writer::open(&s.location, &s.spool, s.spool_max, s.first_retry)?;
        let notes = writer
            .store()
            .map(|st| st.notes().to_vec())
            .unwrap_or_default();
        let mut h = NodeHistory {
            writer,
            machine: s.machine.clone(),
            source: s.source.clone(),
            previous: None,
            previous_read: false,
        };
        h.read_previous()?;
        Ok((h, notes))
    }

    /// The machine's last calibration, read once the history is reached.
    fn read_previous(&mut self) -> anyhow::Result<()> {
        if self.previous_read {
            return Ok(());
        }
        if let Some(store) = self.writer.store() {
            if let Some(last) = store.calibrations(&self.machine)?.pop() {
                self.previous = Some(last.record);
            }
            self.previous_read = true;
        }
        Ok(())
    }

    /// Where it is (a URL without its password) and the machine.
    pub fn describe(&self) -> String {
        format!("machine {} in {}", self.machine, self.writer.describe())
    }

    /// Why the server is away, while it is.
    pub fn away(&self) -> Option<&str> {
        self.writer.away()
    }

    /// Tries a server away again when due and moves the waiting records in; what to say,
    /// when something changed. Settings the server now refuses are an error.
    pub fn retry(&mut self) -> anyhow::Result<Option<Said>> {
        let Some(r) = self.writer.retry(false)? else {
            return Ok(None);
        };
        Ok(Some(match r {
            Retried::Reconnected { flushed, refused } => {
                // what the history holds now is the previous of the next calibration
                self.previous_read = false;
                self.read_previous()?;
                let dropped = if refused.is_empty() {
                    String::new()
                } else {
                    format!(
                        "; {} refused by it and not recorded: {}",
                        refused.len(),
                        refused.join("; ")
                    )
                };
                Said {
                    ok: refused.is_empty(),
                    text: format!(
                        "history: {} answers again: {flushed} waiting records recorded{dropped}",
                        self.writer.describe()
                    ),
                }
            }
            Retried::StillAway(why) => Said {
                ok: false,
                text: format!(
                    "history: away ({why}): retrying, {} records waiting",
                    self.writer.waiting()
                ),
            },
        }))
    }

    /// The /diagnostics values: records waiting, and the server's state.
    pub fn values(&self) -> [(&'static str, String); 2] {
        [
            ("history_waiting", self.writer.waiting().to_string()),
            (
                "history_server",
                self.writer
                    .away()
                    .map_or_else(|| "connected".to_owned(), |w| format!("away: {w}")),
            ),
        ]
    }

    /// Records a calibration now: recorded (and what changed since the previous one),
    /// queued (how many wait, and why), or not recorded (why).
    pub fn calibration(&mut self, o: &Calibrated) -> Said {
        let held_out = crate::units::um_from_m(o.val_rms_m);
        let record = record_of(&Made {
            machine: &self.machine,
            at_s: rpkm_history::schema::now_s(),
            source: &self.source,
            campaign: o.campaign,
            calibration: o.calibration,
            noise: o.noise,
            // the node calibrates under the default tolerance prior, or selects without one
            selection: &Selection::Prior(Prior::default()),
            held_out_rms_um: held_out.is_finite().then_some(held_out),
            verdict: o.verdict.map(str::to_owned),
        });
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                return Said {
                    ok: false,
                    text: format!("not recorded: {e:#}"),
                }
            }
        };
        if let Err(e) = self.read_previous() {
            return Said {
                ok: false,
                text: format!("not recorded: {e:#}"),
            };
        }
        let outcome = self.writer.calibration(&record);
        let said = self.since_previous(&record);
        let (ok, text) = match outcome {
            RecordOutcome::Recorded(Some(id)) => (true, format!("recorded as {id}; {said}")),
            RecordOutcome::Recorded(None) => (true, format!("already recorded; {said}")),
            RecordOutcome::Queued { waiting, why } => (
                false,
                format!("queued, {waiting} waiting for the history ({why}); {said}"),
            ),
            RecordOutcome::Failed(why) => {
                return Said {
                    ok: false,
                    text: format!("not recorded: {why}"),
                }
            }
        };
        self.previous = Some(record);
        Said { ok, text }
    }

    /// What changed since the previous calibration, in words (and whether it was the same
    /// campaign: then the two are not independent measurements).
    fn since_previous(&self, record: &CalibrationRecord) -> String {
        match &self.previous {
            Some(p) if p.campaign.digest == record.campaign.digest => format!(
                "the same campaign as the previous calibration (SHA-256 {}...): not a new \
                 measurement of the machine",
                &record.campaign.digest[..record.campaign.digest.len().min(12)]
            ),
            Some(p) => {
                let change = rpkm_core::history::change(&p.estimate(), &record.estimate());
                words::since_previous(&change, p)
            }
            None if !self.previous_read => {
                "the previous calibration unknown until the history answers".to_owned()
            }
            None => format!("the first calibration of {} in the history", self.machine),
        }
    }

    /// Records the online tracker's step or settled tie of `r` (said as `message`), if it
    /// has one; what to add to the message where it was not recorded at once.
    pub fn event(&mut self, r: &OnlineReport, message: &str) -> Option<String> {
        let (kind, parameter, change, sigma) = if let Some(s) = &r.step {
            let who = match s.alternative {
                Some(other) => format!("{} or {}", state_name(s.param), state_name(other)),
                None => state_name(s.param).to_owned(),
            };
            (EventKind::Step, who, s.change, Some(s.sigma))
        } else if let Some(t) = &r.resolved {
            (
                EventKind::TieSettled,
                state_name(t.param).to_owned(),
                t.change,
                None,
            )
        } else {
            return None;
        };
        match self.writer.event(&EventRecord {
            machine: self.machine.clone(),
            at_s: rpkm_history::schema::now_s(),
            source: self.source.clone(),
            kind,
            parameter: Some(parameter),
            change: Some(change),
            sigma,
            stream_t_s: Some(r.t),
            message: message.to_owned(),
        }) {
            RecordOutcome::Recorded(_) => None,
            RecordOutcome::Queued { waiting, why } => {
                Some(format!("history: event queued, {waiting} waiting ({why})"))
            }
            RecordOutcome::Failed(why) => Some(format!("history: event not recorded: {why}")),
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_machine_is_the_namespace() {
        use super::default_machine;
        assert_eq!(default_machine("rpkm/calibrator", "calibrator"), "rpkm");
        assert_eq!(
            default_machine("/machine_a/calibrator", "calibrator"),
            "machine_a"
        );
        assert_eq!(
            default_machine("/plant/cell_2/calibrator", "calibrator"),
            "plant_cell_2"
        );
    }
}
