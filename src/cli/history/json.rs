//! The analysis as `rpkm history --json` writes it.

use rpkm_history::{CalibrationRecord, Stored};
use rpkm_nodes::history::{words, Analysis};

/// The analysis as JSON (mm, rad; slopes per month; times UTC Unix seconds): what
/// `rpkm history --json` writes.
pub fn to_json(
    machine: &str,
    cals: &[Stored<CalibrationRecord>],
    a: &Analysis,
) -> serde_json::Value {
    use rpkm_core::params::NAMES;
    let change = a.change.as_ref().map(|((i, j), c)| {
        serde_json::json!({
            "from": cals[*i].id,
            "to": cals[*j].id,
            "params": c.params.iter().map(|p| serde_json::json!({
                "name": NAMES[p.param],
                "change": p.change,
                "sigma": p.sigma,
                "z": p.z(),
                "seen": p.seen,
                "flagged": p.flagged(),
            })).collect::<Vec<_>>(),
            "joint": c.joint,
            "largest": c.largest.map(|l| serde_json::json!({
                "name": NAMES[l.param],
                "z": l.z,
                "among": l.among,
                "p_single": l.p_single,
                "p_largest": l.p_largest,
            })),
            "verdict": c.verdict(),
        })
    });
    let trends: Vec<serde_json::Value> = a
        .trends
        .iter()
        .map(|t| {
            serde_json::json!({
                "name": NAMES[t.param],
                "points": t.points.iter().map(|(k, _)| cals[*k].id).collect::<Vec<_>>(),
                "trend": t.trend.map(|tr| serde_json::json!({
                    "since": t.points.get(tr.from).map(|p| cals[p.0].id),
                    "points": tr.points,
                    "slope_per_month": tr.slope * words::MONTH_S,
                    "sigma_per_month": tr.sigma_slope * words::MONTH_S,
                    "z": tr.z(),
                    "chi2": tr.chi2,
                    "dof": tr.dof,
                })),
                "significant": t.significant(),
                "tolerance": t.tolerance,
                "crossing": t.crossing,
            })
        })
        .collect();
    serde_json::json!({
        "machine": machine,
        "calibrations": cals,
        "change": change,
        "trends": trends,
    })
}
