//! The history as a table: one row per calibration (time, campaign, fit, held-out RMS), each
//! parameter's value and σ beside it, empty where that calibration did not determine it (its
//! value there is the prior's, not a measurement).

use rpkm_core::params::{Model, NAMES};
use rpkm_history::{CalibrationRecord, Stored};
use std::fmt::Write as _;

/// A CSV field: quoted where it holds a comma, a quote or a line break.
fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}

/// The CSV of `cals` (mm, rad, µm).
pub fn table(cals: &[Stored<CalibrationRecord>]) -> String {
    let params = Model::M29.params();
    let mut out = String::from(
        "id,at,campaign,campaign_sha256,poses,model,chi2_per_dof,held_out_rms_um,determined",
    );
    for &i in &params {
        let _ = write!(out, ",{0},{0}_sigma", NAMES[i]);
    }
    out.push('\n');
    for c in cals {
        let r = &c.record;
        let e = r.estimate();
        let _ = write!(
            out,
            "{},{},{},{},{},{},{},{},{}",
            c.id,
            chrono::DateTime::from_timestamp(r.at_s, 0)
                .map_or_else(|| r.at_s.to_string(), |d| d.to_rfc3339()),
            field(&r.campaign.name),
            r.campaign.digest,
            r.campaign.poses,
            r.model.number(),
            r.chi2_per_dof,
            r.held_out_rms_um.map_or(String::new(), |v| v.to_string()),
            r.determined
                .map_or(String::new(), |(n, of)| format!("{n}/{of}"))
        );
        for &i in &params {
            if e.determined(i) {
                let _ = write!(out, ",{},{}", e.params[i], e.sigma(i));
            } else {
                out.push_str(",,");
            }
        }
        out.push('\n');
    }
    out
}
