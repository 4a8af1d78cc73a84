//! The calibrator's record of its machine (parameter `history`: an SQLite file or a
//! PostgreSQL URL; `history_machine`: the machine's name, the node's namespace by default):
//! each calibration is recorded, with what changed since the previous calibration of this
//! machine in the history said on /diagnostics, and each step the online tracker names or
//! tie it settles is recorded as an event. A record that fails is said (WARN), never
//! retried in silence; the node goes on calibrating.

use super::online_tracker::{state_name, OnlineReport};
use crate::history::{record_of, words, Made};
use rpkm_core::calib::{Calibration, Prior, Selection};
use rpkm_core::campaign::Campaign;
use rpkm_core::variance::NoiseEstimate;
use rpkm_history::{CalibrationRecord, EventRecord, Store};

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

/// The open history of the node's machine.
pub struct NodeHistory {
    store: Store,
    machine: String,
    /// The node's status name: who recorded.
    source: String,
    /// The last calibration of this machine in the history (another cell's included).
    previous: Option<CalibrationRecord>,
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

impl NodeHistory {
    /// Opens (and migrates) the store at `location` for `machine`.
    pub fn open(location: &str, machine: &str, source: &str) -> anyhow::Result<NodeHistory> {
        let mut store = Store::open(location)?;
        let previous = store.calibrations(machine)?.pop().map(|s| s.record);
        Ok(NodeHistory {
            store,
            machine: machine.to_owned(),
            source: source.to_owned(),
            previous,
        })
    }

    /// Where it is (a URL without its password) and the machine.
    pub fn describe(&self) -> String {
        format!("machine {} in {}", self.machine, self.store.location())
    }

    /// Records a calibration now; what changed since the previous one, in words.
    pub fn calibration(&mut self, o: &Calibrated) -> anyhow::Result<String> {
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
        let id = self.store.record_calibration(&record)?;
        let said = match &self.previous {
            Some(p) => {
                let change = rpkm_core::history::change(&p.estimate(), &record.estimate());
                words::since_previous(&change, p)
            }
            None => format!("the first calibration of {} in the history", self.machine),
        };
        self.previous = Some(record);
        Ok(match id {
            Some(id) => format!("recorded as {id}; {said}"),
            None => format!("already recorded; {said}"),
        })
    }

    /// Records the online tracker's step or settled tie of `r` (said as `message`), if it
    /// has one.
    pub fn event(&mut self, r: &OnlineReport, message: &str) -> anyhow::Result<()> {
        let (kind, parameter, change, sigma) = if let Some(s) = &r.step {
            let who = match s.alternative {
                Some(other) => format!("{} or {}", state_name(s.param), state_name(other)),
                None => state_name(s.param).to_owned(),
            };
            ("step", who, s.change, Some(s.sigma))
        } else if let Some(t) = &r.resolved {
            (
                "tie_settled",
                state_name(t.param).to_owned(),
                t.change,
                None,
            )
        } else {
            return Ok(());
        };
        self.store.record_event(&EventRecord {
            machine: self.machine.clone(),
            at_s: rpkm_history::schema::now_s(),
            source: self.source.clone(),
            kind: kind.to_owned(),
            parameter: Some(parameter),
            change: Some(change),
            sigma,
            stream_t_s: Some(r.t),
            message: message.to_owned(),
        })?;
        Ok(())
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
