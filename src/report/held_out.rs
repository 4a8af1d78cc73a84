//! The held-out residual pose by pose: what the held-out judge judged, against time and
//! along the workspace, for the current model and the model with the named effect, so that
//! the judge's "follows" line can be seen (a residual that grows with time, or with y).

use super::contents::Report;
use super::sections::figure;
use crate::plot::{self, Marker, Series};
use rpkm_core::diagnose::held_out::poses::{residuals, HeldOutResidual};
use rpkm_core::diagnose::ModelDiagnosis;
use rpkm_core::units::um_from_mm;

/// The section, empty without a held-out campaign or its judge.
pub fn section(r: &Report) -> String {
    let Some(val) = r.validation else {
        return String::new();
    };
    let of = |d: &ModelDiagnosis| {
        d.held_out
            .as_ref()
            .and_then(|h| residuals(val, h).ok())
            .unwrap_or_default()
    };
    let before = of(r.before);
    if before.is_empty() {
        return String::new();
    }
    let after = r.after.map(of).unwrap_or_default();
    let judge = r
        .before
        .held_out
        .as_ref()
        .map(rpkm_nodes::words::held_out_judge)
        .unwrap_or_default();
    let mut o = format!(
        "<section id=\"held-out\"><h2>The held-out residual, pose by pose</h2><p>{}</p><div class=\"row\">",
        plot::escape(&judge)
    );
    for (label, at) in [
        (
            "t (s)",
            (|p: &HeldOutResidual| p.t) as fn(&HeldOutResidual) -> f64,
        ),
        ("nominal TCP y (mm)", |p: &HeldOutResidual| p.y_mm),
    ] {
        let mut series = by_direction(&before, "before", at);
        series.extend(by_direction(&after, "after", at));
        let svg = plot::scatter(
            &format!("held-out residual against {label}"),
            label,
            "model − measured, setup's zero removed (µm)",
            &series,
        );
        o.push_str(&figure(
            &svg,
            "Each point a held-out TCP reading (the JSON's held_out_poses): before, the current \
             model; after, with the named effect.",
        ));
    }
    o.push_str("</div></section>");
    o
}

/// One series per coordinate (x, y, r) of `rows`, named `model direction`, at `at`.
fn by_direction(
    rows: &[HeldOutResidual],
    model: &str,
    at: fn(&HeldOutResidual) -> f64,
) -> Vec<Series> {
    ["x", "y", "r"]
        .iter()
        .filter_map(|dir| {
            let markers: Vec<Marker> = rows
                .iter()
                .filter(|p| p.direction == *dir)
                .map(|p| Marker {
                    x: at(p),
                    y: um_from_mm(p.residual),
                    hover: format!(
                        "line {}: t {:.0} s, x {:.1}, y {:.1} mm: {:.2} µm",
                        p.line,
                        p.t,
                        p.x_mm,
                        p.y_mm,
                        um_from_mm(p.residual)
                    ),
                })
                .collect();
            (!markers.is_empty()).then(|| Series {
                name: format!("{model} {dir}"),
                markers,
            })
        })
        .collect()
}
