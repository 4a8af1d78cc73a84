//! The noise a campaign showed against its rating, and where each rating comes from: the
//! spec's figures, rpkm's own where the spec gives none, or `--noise`.

use super::figures::display_unit;
use rpkm_core::variance::GroupNoise;

/// A group's estimated noise is called off its rating outside this ratio band.
const RATED_BAND: std::ops::RangeInclusive<f64> = 0.77..=1.3;

/// "encoder 2.5x noisier than stated (0.50 µm estimated against 0.20 µm, rpkm's assumption:
/// the spec gives no encoder noise; --noise encoder=MM states another)", for every group off
/// its rating: the rating it was compared with, where that rating comes from, and the option
/// that states another.
pub fn noise(groups: &[GroupNoise]) -> String {
    let off: Vec<String> = groups
        .iter()
        .filter(|g| g.estimated_from_data && g.assumed > 0.0)
        .filter(|g| !RATED_BAND.contains(&(g.estimated / g.assumed)))
        .map(|g| {
            let ratio = g.estimated / g.assumed;
            let (_, unit) = display_unit(g.unit);
            let (source, option, per) = rating_of(g.group);
            let source = if g.default_rating {
                source
            } else {
                "as stated with --noise"
            };
            let stated = format!(
                "{:.2} {unit} {} against {:.2} {unit}, {source}; --noise {option}={per} states \
                 another",
                g.estimated,
                if g.capped { "capped" } else { "estimated" },
                g.assumed
            );
            if g.capped {
                // a bound of the estimation, not a figure of the campaign
                return format!(
                    "{} at the estimation's cap, {ratio:.0}x its stated level ({stated}): the \
                     residuals ask for {}, so its level is a bound, not an estimate",
                    g.group,
                    if ratio > 1.0 { "more" } else { "less" }
                );
            }
            let how = if ratio > 1.0 {
                format!("{ratio:.1}x noisier")
            } else {
                format!("{:.1}x quieter", 1.0 / ratio)
            };
            format!("{} {how} than stated ({stated})", g.group)
        })
        .collect();
    off.join(", ")
}

/// A group's estimated level as a table shows it: "20.000", or "≥20.000" (or "≤") where it
/// is the estimation's cap, not an estimate.
pub fn estimated_level(g: &GroupNoise) -> String {
    let bound = match (g.capped, g.estimated >= g.assumed) {
        (false, _) => "",
        (true, true) => "≥",
        (true, false) => "≤",
    };
    format!("{bound}{:.3}", g.estimated)
}

/// Who stated a group's level, in a table's few words: "the spec", "rpkm (spec: none)" or
/// "--noise".
pub fn rated_by(g: &GroupNoise) -> &'static str {
    if !g.default_rating {
        return "--noise";
    }
    if rating_of(g.group).0.starts_with("the spec's") {
        "the spec"
    } else {
        "rpkm (spec: none)"
    }
}

/// Where a noise group's default rating comes from (`NoiseModel::default`, which follows the
/// spec's figures where it gives one), the `--noise` name that states another, and its unit.
fn rating_of(group: &str) -> (&'static str, &'static str, &'static str) {
    match group {
        "lt" => ("the spec's 5 µm along the beam", "lt_along", "MM"),
        "lt_across" => (
            "the spec's 18 µm + 3 µm/m across the beam at the campaign's mean distance",
            "lt_across",
            "MM",
        ),
        "kgm" => ("the spec's 1 µm for the grid encoder", "kgm", "MM"),
        "dbb" => ("the spec's 1 µm for the ball-bar", "dbb", "MM"),
        "li" => ("the spec's 1 µm for the interferometer", "li", "MM"),
        "psi" => ("the spec's 1 µrad for the angle optics", "psi", "RAD"),
        "encoder" => (
            "rpkm's assumption: the spec gives no encoder noise",
            "encoder",
            "MM",
        ),
        "drive_position" => (
            "rpkm's assumption: the spec gives no encoder noise",
            "drive_position",
            "MM",
        ),
        "force" => (
            "rpkm's assumption: the spec gives no drive force noise",
            "force",
            "N",
        ),
        _ => ("the default rating", "NAME", "VALUE"),
    }
}
