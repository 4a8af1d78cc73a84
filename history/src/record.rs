//! What is recorded: a calibration with what makes it comparable with the next, and an event
//! of the online tracker. Plain values (mm, rad, µm; times UTC Unix seconds), so that a
//! record reads back equal to what was written, from either database.

use nalgebra::SMatrix;
use rpkm_core::history::Estimate;
use rpkm_core::params::{Model, Params, N_PARAMS};

/// The campaign a calibration was made from: enough to tell whether two calibrations saw the
/// same measurements.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CampaignId {
    /// Its file or name.
    pub name: String,
    /// SHA-256 of its poses as the campaign grammar writes them (hex), the same for a file
    /// and for the messages that carried it.
    pub digest: String,
    pub poses: u64,
    /// Rows the calibration used (after outliers).
    pub rows: u64,
}

/// One noise group's level: stated, and as the campaign showed it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NoiseLevel {
    pub group: String,
    pub unit: String,
    pub stated: f64,
    pub estimated: f64,
    pub dof: f64,
}

/// A calibration of one machine.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CalibrationRecord {
    pub machine: String,
    /// When it was made (UTC Unix seconds).
    pub at_s: i64,
    /// Who made it: `rpkm calibrate`, or the calibrator node's name.
    pub source: String,
    pub campaign: CampaignId,
    pub model: Model,
    /// The effects in the model with their parameters (JSON, as `rpkm calibrate --json`
    /// writes `effects`); `[]` without any.
    pub effects: serde_json::Value,
    pub params: Params,
    /// Posterior covariance (mm, rad; zero rows and columns for parameters held).
    #[serde(skip)]
    pub covariance: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// Each parameter's manufacturing tolerance (one σ, the calibration's prior).
    pub tolerance: [f64; N_PARAMS],
    /// Parameter combinations determined better than their tolerance, of how many.
    pub determined: Option<(u64, u64)>,
    pub noise: Vec<NoiseLevel>,
    pub chi2_per_dof: f64,
    /// TCP RMS on held-out poses after the calibration, µm (none without held-out data).
    pub held_out_rms_um: Option<f64>,
    /// The diagnosis's verdict in words (none when it was not diagnosed).
    pub verdict: Option<String>,
}

impl CalibrationRecord {
    /// The calibration as the core's history arithmetic reads it (time in s).
    pub fn estimate(&self) -> Estimate {
        Estimate {
            t_s: self.at_s as f64,
            model: self.model,
            params: self.params,
            covariance: self.covariance,
            tolerance: self.tolerance,
        }
    }
}

/// Something the online tracker said: a step it named, a tie it settled.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EventRecord {
    pub machine: String,
    pub at_s: i64,
    pub source: String,
    /// What the tracker said (stored as `step`, `tie_settled`).
    pub kind: EventKind,
    /// The parameter it names, if one.
    pub parameter: Option<String>,
    /// Its change and σ (mm, rad).
    pub change: Option<f64>,
    pub sigma: Option<f64>,
    /// Where in the drive stream, s.
    pub stream_t_s: Option<f64>,
    /// In words, as /diagnostics said it.
    pub message: String,
}

/// What an [`EventRecord`] records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// A parameter stepped (the tracker named its change).
    Step,
    /// A tie between two parameters settled by a separating motion.
    TieSettled,
}

impl EventKind {
    /// Every kind, in the order the doc lists them.
    pub const ALL: [EventKind; 2] = [EventKind::Step, EventKind::TieSettled];

    /// As stored and printed.
    pub fn as_str(self) -> &'static str {
        match self {
            EventKind::Step => "step",
            EventKind::TieSettled => "tie_settled",
        }
    }

    /// The kind stored as `text`; None for a kind this rpkm does not write.
    pub fn parse(text: &str) -> Option<EventKind> {
        EventKind::ALL.into_iter().find(|k| k.as_str() == text)
    }
}

impl std::fmt::Display for EventKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.as_str())
    }
}

/// A record read back, with its key in the database.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Stored<T> {
    pub id: i64,
    pub record: T,
}
