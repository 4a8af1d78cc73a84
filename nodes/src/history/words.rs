//! The history in sentences: what moved between two calibrations ("l3 +0.101 mm ± 0.004
//! (25σ) between 2026-03-01 and 2026-03-09"), what cannot be known, whether anything changed
//! at all, the trends ("l1 creeps +20.0 µm per month (23σ)") and when a parameter leaves
//! its tolerance ("l1 leaves ±0.100 mm in 4.5 ± 0.3 months").

use super::analysis::{Analysis, ParamTrend};
use rpkm_core::history::{Change, ParamChange, Seen, FLAG_SIGMA};
use rpkm_core::params::{unit, Unit, NAMES};
use rpkm_history::{CalibrationRecord, Stored};

/// Seconds of a mean month (365.25 / 12 days).
pub const MONTH_S: f64 = 30.4375 * 86_400.0;

/// The UTC date of `at_s` (`2026-03-01`).
pub fn date(at_s: i64) -> String {
    chrono::DateTime::from_timestamp(at_s, 0)
        .map_or_else(|| format!("{at_s} s"), |d| d.format("%Y-%m-%d").to_string())
}

/// The UTC date and time of `at_s` (`2026-03-01 10:00 UTC`).
pub fn date_time(at_s: i64) -> String {
    chrono::DateTime::from_timestamp(at_s, 0).map_or_else(
        || format!("{at_s} s"),
        |d| d.format("%Y-%m-%d %H:%M UTC").to_string(),
    )
}

/// A change's scale and unit: mm for lengths, mrad for angles.
pub fn change_unit(param: usize) -> (f64, &'static str) {
    match unit(param) {
        Unit::Mm => (1.0, "mm"),
        Unit::Rad => (1e3, "mrad"),
    }
}

/// A rate's scale and unit: µm or µrad.
fn rate_unit(param: usize) -> (f64, &'static str) {
    match unit(param) {
        Unit::Mm => (1e3, "µm"),
        Unit::Rad => (1e6, "µrad"),
    }
}

/// "l3 +0.101 mm ± 0.004 (25.3σ)".
pub fn moved(p: &ParamChange) -> String {
    let (s, u) = change_unit(p.param);
    let z = p
        .z()
        .map_or(String::new(), |z| format!(" ({:.1}σ)", z.abs()));
    format!(
        "{} {:+.3} {u} ± {:.3}{z}",
        NAMES[p.param],
        p.change * s,
        p.sigma * s
    )
}

/// The sentences of a change from `a` to `b`: what moved beyond 3σ (or that nothing did),
/// what neither could see, and the test over every direction both determined.
pub fn change(c: &Change, a: &CalibrationRecord, b: &CalibrationRecord) -> Vec<String> {
    let between = format!("between {} and {}", date(a.at_s), date(b.at_s));
    let mut lines: Vec<String> = c
        .flagged()
        .iter()
        .map(|p| format!("{} {between}", moved(p)))
        .collect();
    if lines.is_empty() {
        lines.push(format!(
            "nothing moved beyond {FLAG_SIGMA:.0}σ {between} among the parameters both \
             calibrations determined"
        ));
    }
    let unknown: Vec<&str> = c
        .params
        .iter()
        .filter(|p| p.seen != Seen::Both)
        .map(|p| NAMES[p.param])
        .collect();
    if !unknown.is_empty() {
        lines.push(format!(
            "unknown (not determined by both campaigns, so their change is not zero but not \
             seen): {}",
            unknown.join(", ")
        ));
    }
    if let Some(j) = &c.joint {
        let whole = if j.p_value < 1e-3 {
            "the machine changed"
        } else {
            "no change beyond the noise"
        };
        lines.push(format!(
            "over the {} directions both determined: χ² {:.1}, p = {:.2e}: {whole}",
            j.directions, j.chi2, j.p_value
        ));
    }
    lines
}

/// What changed since the previous calibration, in one line (the calibrator's /diagnostics).
pub fn since_previous(c: &Change, previous: &CalibrationRecord) -> String {
    let flagged = c.flagged();
    let moved: Vec<String> = flagged.iter().map(moved).collect();
    let when = date_time(previous.at_s);
    if moved.is_empty() {
        format!("since the previous calibration ({when}): nothing moved beyond {FLAG_SIGMA:.0}σ")
    } else {
        format!(
            "since the previous calibration ({when}): {}",
            moved.join(", ")
        )
    }
}

/// "l1 creeps +20.0 µm per month (23.4σ) over the 11 calibrations since 2026-03-09", or None
/// without a significant trend.
pub fn trend(t: &ParamTrend, cals: &[Stored<CalibrationRecord>]) -> Option<String> {
    let line = t.trend.filter(|_| t.significant())?;
    let (s, u) = rate_unit(t.param);
    let first = t.points.get(line.from).and_then(|p| cals.get(p.0))?;
    Some(format!(
        "{} creeps {:+.1} {u} per month ({:.1}σ) over the {} calibrations since {}",
        NAMES[t.param],
        line.slope * MONTH_S * s,
        line.z().abs(),
        line.points,
        date(first.record.at_s)
    ))
}

/// When a trend leaves its band, seen from `now_s` (the latest calibration): "l1 leaves
/// ±0.100 mm in 4.5 ± 0.3 months (about 2027-01-20)", or "l1 left ±0.100 mm about
/// 2026-09-14 ± 9 days".
pub fn crossing(t: &ParamTrend, now_s: i64) -> Option<String> {
    let c = t.crossing?;
    let (s, u) = change_unit(t.param);
    let name = NAMES[t.param];
    let band = format!("±{:.3} {u}", t.tolerance * s);
    let at = rpkm_core::convert::round_i64(c.t_s);
    let ahead = (c.t_s - now_s as f64) / MONTH_S;
    Some(if ahead >= 0.0 {
        format!(
            "{name} leaves {band} in {ahead:.1} ± {:.1} months (about {})",
            c.sigma_s / MONTH_S,
            date(at)
        )
    } else {
        format!(
            "{name} left {band} about {} ± {:.0} days",
            date(at),
            c.sigma_s / 86_400.0
        )
    })
}

/// Every sentence of an analysis: the change, then the trends with their crossings.
pub fn summary(a: &Analysis, cals: &[Stored<CalibrationRecord>]) -> Vec<String> {
    let mut lines = Vec::new();
    if let Some(((i, j), c)) = &a.change {
        lines.extend(change(c, &cals[*i].record, &cals[*j].record));
    }
    let now = cals.last().map_or(0, |c| c.record.at_s);
    for t in &a.trends {
        if let Some(line) = trend(t, cals) {
            lines.push(line);
            lines.extend(crossing(t, now));
        }
    }
    lines
}
