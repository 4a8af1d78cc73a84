//! The history in sentences: what moved between two calibrations ("l3 +0.101 mm ± 0.004
//! (25σ) between 2026-03-01 and 2026-03-09"), what cannot be known, whether anything changed
//! at all (the joint χ² and the largest single change in one statement), the trends ("l1 creeps +20.0 µm per month (23σ)") and when a parameter leaves
//! its tolerance ("l1 leaves ±0.100 mm in 4.5 ± 0.3 months").

use super::analysis::{Analysis, ParamTrend};
use rpkm_core::history::{Change, ChangeVerdict, ParamChange, Seen, CHANGE_P_VALUE, FLAG_SIGMA};
use rpkm_core::params::{unit, Unit, NAMES};
use rpkm_history::{CalibrationRecord, Stored};
use std::fmt::Write as _;

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
    lines.extend(whole(c));
    lines
}

/// A p-value in two significant digits: "0.033", "0.18", "5.8e-6".
fn p_text(p: f64) -> String {
    if p >= 0.1 {
        format!("{p:.2}")
    } else if p >= 0.01 {
        format!("{p:.3}")
    } else {
        format!("{p:.1e}")
    }
}

/// The whole machine in one statement: the verdict, then the largest single change read as
/// the largest of the parameters both determined, and the joint χ² over every direction
/// both determined ("no change beyond the noise: largest single change l4 3.1σ, expected of
/// the largest of 29 by chance (p = 0.055); joint χ² 12.1 on 24 directions, p = 0.033").
pub fn whole(c: &Change) -> Option<String> {
    let (largest, verdict) = (c.largest?, c.verdict()?);
    let name = NAMES[largest.param];
    let head = match verdict {
        ChangeVerdict::Changed => "the machine changed".to_owned(),
        ChangeVerdict::OneChanged => format!("{name} changed"),
        ChangeVerdict::NoChange => "no change beyond the noise".to_owned(),
    };
    let reading = if largest.p_largest < CHANGE_P_VALUE {
        "beyond what the largest of"
    } else {
        "expected of the largest of"
    };
    let by_chance = if largest.p_largest < CHANGE_P_VALUE {
        "reaches by chance"
    } else {
        "by chance"
    };
    let mut line = format!(
        "{head}: largest single change {name} {:.1}σ, {reading} {} {by_chance} (p = {})",
        largest.z.abs(),
        largest.among,
        p_text(largest.p_largest)
    );
    if let Some(j) = &c.joint {
        let _ = write!(
            line,
            "; joint χ² {:.1} on {} directions, p = {}",
            j.chi2,
            j.directions,
            p_text(j.p_value)
        );
        if verdict == ChangeVerdict::OneChanged {
            line.push_str(" (one change spread over all of them)");
        }
    }
    Some(line)
}

/// What changed since the previous calibration, in one line (the calibrator's /diagnostics):
/// the flags, then the whole machine's statement ([`whole`]).
pub fn since_previous(c: &Change, previous: &CalibrationRecord) -> String {
    let flagged = c.flagged();
    let moved: Vec<String> = flagged.iter().map(moved).collect();
    let when = date_time(previous.at_s);
    let mut line = if moved.is_empty() {
        format!("since the previous calibration ({when}): nothing moved beyond {FLAG_SIGMA:.0}σ")
    } else {
        format!(
            "since the previous calibration ({when}): {}",
            moved.join(", ")
        )
    };
    if let Some(w) = whole(c) {
        line = format!("{line}; {w}");
    }
    line
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

#[cfg(test)]
mod tests {
    use super::*;
    use rpkm_core::calib::Prior;
    use rpkm_core::history::{change as change_of, Estimate};
    use rpkm_core::params::{Model, Params, L1, L4, N_PARAMS};

    /// Two calibrations of model 29 that determined every parameter to 0.3 of its tolerance,
    /// the second moved by `z[i]` σ of the change (σ = 0.3 √2 tolerance).
    fn moved_by(z: &[f64; N_PARAMS]) -> Change {
        let tol: [f64; N_PARAMS] = std::array::from_fn(|i| Prior::default().sigma(i));
        let before = Estimate {
            t_s: 0.0,
            model: Model::M29,
            params: Params::nominal(),
            covariance: nalgebra::SMatrix::from_fn(|i, j| {
                if i == j {
                    (0.3 * tol[i]).powi(2)
                } else {
                    0.0
                }
            }),
            tolerance: tol,
        };
        let mut after = before.clone();
        for i in 0..N_PARAMS {
            after.params[i] += z[i] * 0.3 * std::f64::consts::SQRT_2 * tol[i];
        }
        change_of(&before, &after)
    }

    fn alone(param: usize, z: f64) -> [f64; N_PARAMS] {
        let mut out = [0.0; N_PARAMS];
        out[param] = z;
        out
    }

    /// The reference values (scipy): 2·Q(3.1) = 1.935e-3, 1 − (1 − that)^29 = 0.0546;
    /// 2·Q(5) = 5.733e-7, as the largest of 29 1.663e-5; 2·Q(1.6) = 0.1096, of 29 0.965;
    /// P(χ²₂₉ ≥ 9.61) = 0.99973, P(χ²₂₉ ≥ 25) = 0.678, P(χ²₂₉ ≥ 65.56) = 1.197e-4.
    #[test]
    fn the_largest_change_and_the_joint_test_are_one_statement() {
        let c = moved_by(&alone(L4, -3.1));
        assert_eq!(
            whole(&c).as_deref(),
            Some(
                "no change beyond the noise: largest single change l4 3.1σ, expected of the \
                 largest of 29 by chance (p = 0.055); joint χ² 9.6 on 29 directions, p = 1.00"
            )
        );
        let c = moved_by(&alone(L4, 5.0));
        assert_eq!(
            whole(&c).as_deref(),
            Some(
                "l4 changed: largest single change l4 5.0σ, beyond what the largest of 29 \
                 reaches by chance (p = 1.7e-5); joint χ² 25.0 on 29 directions, p = 0.68 (one \
                 change spread over all of them)"
            )
        );
        let mut spread = [1.5; N_PARAMS];
        spread[L1] = 1.6;
        let c = moved_by(&spread);
        assert_eq!(
            whole(&c).as_deref(),
            Some(
                "the machine changed: largest single change l1 1.6σ, expected of the largest \
                 of 29 by chance (p = 0.97); joint χ² 65.6 on 29 directions, p = 1.2e-4"
            )
        );
    }
}
