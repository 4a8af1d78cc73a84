//! The machine's history as the command line and the nodes keep and show it: a calibration
//! made into a record ([`record_of`]: its campaign's digest, the tolerance it was judged
//! against), and a machine's records analysed ([`analyse`]: what changed between two, each
//! parameter's trend and when it leaves its tolerance). The arithmetic is the core's
//! (`rpkm_core::history`), the store `rpkm_history`'s; the words are [`words`], the table
//! [`csv`], the page `crate::report::history`.

pub mod csv;
pub mod words;

use rpkm_core::calib::{Calibration, Prior, Selection};
use rpkm_core::campaign::Campaign;
use rpkm_core::history::{change, crossing, trend, Change, Crossing, Point, Trend, FLAG_SIGMA};
use rpkm_core::params::Params;
use rpkm_core::variance::NoiseEstimate;
use rpkm_history::{CalibrationRecord, CampaignId, NoiseLevel, Stored};
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

/// The record of a calibration.
pub fn record_of(m: &Made) -> CalibrationRecord {
    let prior = match m.selection {
        Selection::Prior(p) => *p,
        Selection::Auto { .. } | Selection::List(_) => Prior::default(),
    };
    let cal = m.calibration;
    CalibrationRecord {
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
        effects: serde_json::to_value(&cal.effects).unwrap_or_default(),
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
    }
}

/// A trend is named when its slope exceeds this many σ (as a change is flagged).
pub const TREND_SIGMA: f64 = FLAG_SIGMA;

/// One parameter over a machine's calibrations.
#[derive(Clone, Debug)]
pub struct ParamTrend {
    pub param: usize,
    /// The calibrations that determined it (indices into the history) and their values.
    pub points: Vec<(usize, Point)>,
    /// Its line over the run a line explains (`from` indexes `points`).
    pub trend: Option<Trend>,
    /// When a significant trend leaves nominal ± `tolerance`.
    pub crossing: Option<Crossing>,
    /// The band a trend is judged against (mm, rad): the latest calibration's tolerance, or
    /// the one asked for.
    pub tolerance: f64,
}

impl ParamTrend {
    /// Whether its trend is significant.
    pub fn significant(&self) -> bool {
        self.trend.is_some_and(|t| t.z().abs() >= TREND_SIGMA)
    }
}

/// What a machine's history says.
#[derive(Clone, Debug)]
pub struct Analysis {
    /// The two calibrations compared (indices into the history, earlier first) and what
    /// changed between them.
    pub change: Option<((usize, usize), Change)>,
    /// Every parameter of the latest calibration's model.
    pub trends: Vec<ParamTrend>,
}

/// The analysis of `cals` (oldest first): the change between `pair` (default: the last two)
/// and each parameter's trend; `tolerance` replaces a parameter's band (mm, rad).
pub fn analyse(
    cals: &[Stored<CalibrationRecord>],
    pair: Option<(usize, usize)>,
    tolerance: &[(usize, f64)],
) -> Analysis {
    let pair = pair.or_else(|| (cals.len() >= 2).then(|| (cals.len() - 2, cals.len() - 1)));
    let change = pair.and_then(|(a, b)| {
        let (a, b) = (a.min(b), a.max(b));
        let (ra, rb) = (&cals.get(a)?.record, &cals.get(b)?.record);
        Some(((a, b), change(&ra.estimate(), &rb.estimate())))
    });
    let Some(latest) = cals.last() else {
        return Analysis {
            change,
            trends: Vec::new(),
        };
    };
    let nominal = Params::nominal();
    let trends = latest
        .record
        .model
        .params()
        .into_iter()
        .map(|i| {
            let band = tolerance
                .iter()
                .find(|t| t.0 == i)
                .map_or(latest.record.tolerance[i], |t| t.1);
            param_trend(cals, i, nominal[i], band)
        })
        .collect();
    Analysis { change, trends }
}

fn param_trend(
    cals: &[Stored<CalibrationRecord>],
    i: usize,
    nominal: f64,
    tolerance: f64,
) -> ParamTrend {
    let points: Vec<(usize, Point)> = cals
        .iter()
        .enumerate()
        .filter(|(_, c)| c.record.estimate().determined(i))
        .map(|(k, c)| {
            let e = c.record.estimate();
            (
                k,
                Point {
                    t_s: e.t_s,
                    value: e.params[i],
                    sigma: e.sigma(i),
                },
            )
        })
        .collect();
    let plain: Vec<Point> = points.iter().map(|p| p.1).collect();
    let line = trend(&plain);
    let crossing = line
        .filter(|t| t.z().abs() >= TREND_SIGMA)
        .and_then(|t| crossing(&t, nominal, tolerance));
    ParamTrend {
        param: i,
        points,
        trend: line,
        crossing,
        tolerance,
    }
}

/// The parameters a reader looks at first: flagged in the change, then significant trends,
/// then the rest determined at least [`rpkm_core::history::MIN_POINTS`] times.
pub fn charted(a: &Analysis) -> Vec<&ParamTrend> {
    let flagged = |i: usize| {
        a.change
            .as_ref()
            .is_some_and(|(_, c)| c.params.iter().any(|p| p.param == i && p.flagged()))
    };
    let mut out: Vec<&ParamTrend> = a
        .trends
        .iter()
        .filter(|t| t.points.len() >= rpkm_core::history::MIN_POINTS || flagged(t.param))
        .collect();
    out.sort_by_key(|t| (!flagged(t.param), !t.significant(), t.param));
    out
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
