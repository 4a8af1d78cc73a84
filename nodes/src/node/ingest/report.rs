//! The counts of accepted and rejected samples and their `/diagnostics` status.

use std::collections::HashMap;

use rpkm_msgs::DiagnosticStatus;

use super::validate::{Reject, RejectKind};
use crate::node::status;

/// Accepted and rejected counts.
#[derive(Debug, Clone, Default)]
pub struct Tally {
    /// ActuatorStates published.
    pub accepted_states: u64,
    /// TcpMeasurements published.
    pub accepted_measurements: u64,
    /// Rejects per kind.
    pub rejected: HashMap<RejectKind, u64>,
    /// The last reject's reason.
    pub last_reject: Option<String>,
    /// Samples of a live source taken while the node was not active (a managed node
    /// publishes nothing then).
    pub dropped_inactive: u64,
    rejected_at_last_report: u64,
}

impl Tally {
    /// Counts a reject.
    pub fn reject(&mut self, r: Reject) {
        *self.rejected.entry(r.kind).or_default() += 1;
        self.last_reject = Some(r.detail);
    }

    /// All rejects.
    pub fn rejected_total(&self) -> u64 {
        self.rejected.values().sum()
    }

    /// The /diagnostics status: WARN when samples were rejected since the last report.
    pub fn status(&mut self, node: &str, source: &str) -> DiagnosticStatus {
        let total = self.rejected_total();
        let fresh = total - self.rejected_at_last_report;
        self.rejected_at_last_report = total;
        let (level, message) = if fresh > 0 {
            (
                DiagnosticStatus::WARN,
                format!(
                    "{fresh} samples rejected since the last report; last: {}",
                    self.last_reject.as_deref().unwrap_or("")
                ),
            )
        } else {
            (
                DiagnosticStatus::OK,
                format!(
                    "{} states, {} measurements accepted",
                    self.accepted_states, self.accepted_measurements
                ),
            )
        };
        let mut values = vec![
            ("source", source.to_owned()),
            ("accepted_states", self.accepted_states.to_string()),
            (
                "accepted_measurements",
                self.accepted_measurements.to_string(),
            ),
            ("rejected_total", total.to_string()),
            ("dropped_inactive", self.dropped_inactive.to_string()),
        ];
        for k in RejectKind::ALL {
            values.push((
                k.key(),
                self.rejected.get(&k).copied().unwrap_or(0).to_string(),
            ));
        }
        values.push(("last_reject", self.last_reject.clone().unwrap_or_default()));
        status(level, node, message, values)
    }
}
