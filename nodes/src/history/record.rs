//! A calibration made into the record the history keeps: its campaign's digest, the
//! tolerance it was judged against, the noise it showed; and the time it is recorded at.

use crate::calibration_file::EffectValue;
use rpkm_core::calib::{Calibration, Prior, Selection};
use rpkm_core::campaign::Campaign;
use rpkm_core::variance::NoiseEstimate;
use rpkm_history::{CalibrationRecord, CampaignId, NoiseLevel};
use std::fmt::Write as _;

/// A calibration as it was made, to be recorded.
pub struct Made<'a> {
    pub machine: &'a str,
    /// UTC Unix seconds.
    pub at_s: i64,
    /// `rpkm calibrate`, or the node's name.
    pub source: &'a str,
    /// The campaign calibrated (without its held-out part).
    pub campaign: &'a Campaign,
    pub calibration: &'a Calibration,
    pub noise: &'a NoiseEstimate,
    /// The selection it was made with: its prior's tolerances, the default's without one.
    pub selection: &'a Selection,
    pub held_out_rms_um: Option<f64>,
    pub verdict: Option<String>,
}

/// SHA-256 of the campaign's poses as the grammar writes them, without its comments: the
/// same for a file and for the messages that carried it.
pub fn campaign_digest(c: &Campaign) -> String {
    let bare = Campaign {
        comments: Vec::new(),
        source: String::new(),
        ..c.clone()
    };
    openssl::sha::sha256(bare.to_csv().as_bytes()).iter().fold(
        String::with_capacity(64),
        |mut hex, b| {
            let _ = write!(hex, "{b:02x}");
            hex
        },
    )
}

/// The record of a calibration; its effects as the calibration file writes them
/// ([`EffectValue`]).
pub fn record_of(m: &Made) -> anyhow::Result<CalibrationRecord> {
    let prior = match m.selection {
        Selection::Prior(p) => *p,
        Selection::Auto { .. } | Selection::List(_) => Prior::default(),
    };
    let cal = m.calibration;
    let effects = cal
        .effects
        .iter()
        .filter(|e| e.physical())
        .map(EffectValue::of)
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(CalibrationRecord {
        machine: m.machine.to_owned(),
        at_s: m.at_s,
        source: m.source.to_owned(),
        campaign: CampaignId {
            name: m.campaign.source.clone(),
            digest: campaign_digest(m.campaign),
            poses: m.campaign.poses.len() as u64,
            rows: cal.rows as u64,
        },
        model: cal.model,
        effects: serde_json::to_value(effects)?,
        params: cal.params,
        covariance: cal.covariance,
        tolerance: std::array::from_fn(|i| prior.sigma(i)),
        determined: cal.determined.map(|(n, of)| (n as u64, of as u64)),
        noise: m
            .noise
            .groups
            .iter()
            .map(|g| NoiseLevel {
                group: g.group.to_owned(),
                unit: g.unit.to_owned(),
                stated: g.assumed,
                estimated: g.estimated,
                dof: g.dof,
            })
            .collect(),
        chi2_per_dof: cal.chi2_per_dof,
        held_out_rms_um: m.held_out_rms_um,
        verdict: m.verdict.clone(),
    })
}

/// The time of `--at`: RFC 3339 (`2026-03-01T10:00:00Z`), or a date (`2026-03-01`, midnight
/// UTC); now without one. UTC Unix seconds.
pub fn time_of(at: Option<&str>) -> Result<i64, String> {
    let Some(at) = at.map(str::trim) else {
        return Ok(rpkm_history::schema::now_s());
    };
    if let Ok(t) = chrono::DateTime::parse_from_rfc3339(at) {
        return Ok(t.timestamp());
    }
    chrono::NaiveDate::parse_from_str(at, "%Y-%m-%d")
        .ok()
        .and_then(|d| d.and_hms_opt(0, 0, 0))
        .map(|t| t.and_utc().timestamp())
        .ok_or_else(|| {
            format!("{at}: expected RFC 3339 (2026-03-01T10:00:00Z) or a date (2026-03-01)")
        })
}
