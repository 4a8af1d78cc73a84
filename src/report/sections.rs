//! The sections of the report page.

use super::contents::Report;
use crate::plot::machine::Machine;
use crate::plot::maps::{self, Arrow, MapPoint, View};
use crate::plot::{self, escape, BarOptions, Marker, Series};
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::structure::sparse::nominal_tcp;
use rpkm_core::diagnose::{ModelDiagnosis, ResidualPoint, VerdictKind};
use rpkm_core::params::Params;
use rpkm_core::units::um_from_mm;
use std::fmt::Write as _;

/// A µm figure to one decimal, `-` when absent.
fn um(v: Option<f64>) -> String {
    v.map_or("-".to_owned(), |v| format!("{v:.1}"))
}

/// A figure with its caption.
pub(super) fn figure(svg: &str, caption: &str) -> String {
    format!(
        "<figure class=\"plot\">{svg}<figcaption>{}</figcaption></figure>",
        escape(caption)
    )
}

/// The verdict's name as the JSON spells it.
fn kind(k: VerdictKind) -> &'static str {
    match k {
        VerdictKind::NothingMissing => "nothing missing",
        VerdictKind::MissingEffect => "missing effect",
        VerdictKind::UnexplainedStructure => "unexplained structure",
    }
}

fn verdict_box(label: &str, d: &ModelDiagnosis) -> String {
    let ok = if d.verdict_kind == VerdictKind::NothingMissing {
        " ok"
    } else {
        ""
    };
    // the verdict's sentence starts with its kind
    format!(
        "<div class=\"verdict{ok}\" title=\"{}\"><b>{}</b>: {}</div>",
        kind(d.verdict_kind),
        escape(label),
        escape(&rpkm_nodes::words::verdict(d))
    )
}

/// The parameter combinations each model of the page determined, named by model: the model
/// with effects determines more (or fewer) than the one without.
fn determined(r: &Report) -> String {
    let each: Vec<String> = std::iter::once(r.before)
        .chain(r.after)
        .map(|m| {
            format!(
                "{} in {}",
                m.determined
                    .map_or("all".to_owned(), |(n, of)| format!("{n} of {of}")),
                Report::stage_of(m).model
            )
        })
        .collect();
    each.join(", ")
}

/// Verdict, the error falling effect by effect, the noise against its rating.
pub fn summary(r: &Report) -> String {
    let (c, d) = (r.campaign, r.before);
    let mut o = format!(
        "<section id=\"summary\"><h1>Diagnosis of {}</h1><p class=\"muted\">{} poses; {} rows; \
         parameter combinations the campaign determined better than their tolerance: {}.</p>",
        escape(&c.source),
        c.poses.len(),
        d.points.len(),
        escape(&determined(r))
    );
    o.push_str(&verdict_box("current model", d));
    if let Some(a) = r.after {
        o.push_str(&verdict_box(
            &format!("with {}", a.effects_in_model.join(" + ")),
            a,
        ));
    }
    o.push_str("<h3>The error, effect by effect</h3><div class=\"row\"><table><tr><th>model</th><th>calibration RMS µm</th><th>held-out RMS µm</th><th>χ²/dof under one noise</th></tr>");
    for s in &r.stages {
        let _ = write!(
            o,
            "<tr><td>{}</td><td>{:.1}</td><td>{}</td><td>{:.2}</td></tr>",
            escape(&s.model),
            s.cal_rms_um,
            um(s.val_rms_um),
            s.chi2_per_dof
        );
    }
    let last = &r.after.unwrap_or(d).baseline;
    let floor = um_from_mm(last.noise_floor);
    let _ = write!(
        o,
        "<tr><td>noise floor</td><td></td><td>{floor:.1}</td><td>1</td></tr></table>\
         <p class=\"muted\">χ²/dof: every model's rows weighted by one noise, {}, so that the \
         models compare (under its own estimate each would read about 1).</p>",
        escape(&r.chi2_under)
    );
    if let (Some(rms), Some(zero_floor)) = (
        last.val_rms_relative.map(um_from_mm),
        last.noise_floor_relative.map(um_from_mm),
    ) {
        let _ = write!(
            o,
            "<p>The held-out errors carry the reading each setup was zeroed on: one draw that all \
             its poses share, counted in the floor at its variance. With each setup's zero \
             removed (what a model can predict) the last model's held-out RMS is {rms:.1} µm \
             against a floor of {zero_floor:.1} µm.</p>"
        );
    }
    let mut cats: Vec<String> = r.stages.iter().map(|s| s.model.clone()).collect();
    cats.push("noise floor".to_owned());
    let mut held: Vec<f64> = r
        .stages
        .iter()
        .map(|s| s.val_rms_um.unwrap_or(f64::NAN))
        .collect();
    held.push(floor);
    let mut cal: Vec<f64> = r.stages.iter().map(|s| s.cal_rms_um).collect();
    cal.push(f64::NAN);
    let chart = plot::bar_chart(
        "TCP error per model",
        "RMS (µm)",
        &cats,
        &[
            ("held-out".to_owned(), held),
            ("calibration".to_owned(), cal),
        ],
        &BarOptions::default(),
    );
    o.push_str(&figure(
        &chart,
        "Held-out RMS: poses the calibration never saw.",
    ));
    o.push_str("</div>");
    o.push_str(&noise(r.after.unwrap_or(d)));
    o.push_str("</section>");
    o
}

/// The noise table and chart of the model `d` (the last of the page: the one calibrated):
/// stated against estimated, per group, a cap shown as one.
fn noise(d: &ModelDiagnosis) -> String {
    let model = Report::stage_of(d).model;
    let mut o = format!("<h3>Noise of {}: what the campaign shows against the rating</h3><div class=\"row\"><table><tr><th>group</th><th>rated</th><th>estimated</th><th>ratio</th><th>dof</th></tr>", escape(&model));
    for g in &d.noise_groups {
        let _ = write!(
            o,
            "<tr><td>{}</td><td>{:.3} {u}</td><td>{} {u}</td><td>{:.2}{}</td><td>{:.0}</td></tr>",
            g.group,
            g.assumed,
            escape(&rpkm_nodes::words::estimated_level(g)),
            g.estimated / g.assumed,
            if g.capped {
                " (the estimation's cap: a bound, not an estimate)"
            } else if g.estimated_from_data {
                ""
            } else {
                " (not estimated)"
            },
            g.dof,
            u = rpkm_nodes::words::unit_label(g.unit)
        );
    }
    o.push_str("</table>");
    let cats: Vec<String> = d
        .noise_groups
        .iter()
        .map(|g| format!("{} ({})", g.group, rpkm_nodes::words::unit_label(g.unit)))
        .collect();
    let chart = plot::bar_chart(
        "Noise per group",
        "σ per coordinate (log)",
        &cats,
        &[
            (
                "rated".to_owned(),
                d.noise_groups.iter().map(|g| g.assumed).collect(),
            ),
            (
                "estimated".to_owned(),
                d.noise_groups.iter().map(|g| g.estimated).collect(),
            ),
        ],
        &BarOptions { log: true },
    );
    o.push_str(&figure(
        &chart,
        &format!(
            "Estimated from the residuals of {model} (variance components): the weights of \
             its fit."
        ),
    ));
    o.push_str("</div>");
    o
}

/// The machine (nominal parameters) at the first setup's reset pose, its guides over the
/// campaign's travel; the pose.
fn machine_at_reset(c: &Campaign) -> Option<(Machine, (f64, f64))> {
    let tcp = nominal_tcp(c);
    let at = c
        .setups()
        .iter()
        .find_map(|s| s.reset)
        .and_then(|i| tcp.get(i).copied())
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .unwrap_or((0.0, 1700.0));
    let travel = plot::range(c.poses.iter().flat_map(|p| p.q), 0.0);
    Machine::at(&Params::nominal(), at.0, at.1, travel)
        .ok()
        .map(|m| (m, at))
}

/// The machine at the first setup's reset pose, with every pose of the campaign.
pub fn machine(r: &Report) -> String {
    let c = r.campaign;
    let tcp = nominal_tcp(c);
    let Some((m, at)) = machine_at_reset(c) else {
        return String::new();
    };
    let poses: Vec<(f64, f64, String)> = c
        .poses
        .iter()
        .zip(&tcp)
        .map(|(p, t)| (t.0, t.1, p.instrument.as_str().to_owned()))
        .collect();
    let view = View::around(tcp.iter().copied().filter(|p| p.0.is_finite()));
    let svg = maps::machine_figure("The machine and the campaign", &m, &poses, view);
    format!(
        "<section id=\"machine\"><h2>The machine and the campaign</h2><p class=\"muted\">Guides, carriers, rods and the platform drawn from the geometry at the reset pose (x {:.0}, y {:.0} mm). The maps that follow zoom into the dashed rectangle, where the campaign's poses are; their x axis is stretched to show the pattern.</p>{}</section>",
        at.0,
        at.1,
        figure(&svg, "True scale, nominal parameters.")
    )
}

/// The points of one instrument direction.
fn of<'a>(
    d: &'a ModelDiagnosis,
    instrument: &'a str,
    direction: &'a str,
) -> impl Iterator<Item = &'a ResidualPoint> + Clone {
    d.points
        .iter()
        .filter(move |p| p.instrument == instrument && p.direction == direction)
}

fn map_points<'a>(pts: impl Iterator<Item = &'a ResidualPoint>) -> Vec<MapPoint> {
    pts.map(|p| MapPoint {
        x: p.x,
        y: p.y,
        value: p.value,
        sigma: p.sigma,
        line: p.line,
    })
    .collect()
}

/// The 98th percentile of |values| (a single outlier does not wash out the scale).
fn p98(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.filter(|v| v.is_finite()).map(f64::abs).collect();
    v.sort_by(f64::total_cmp);
    let k = rpkm_core::convert::ceil_count(v.len() as f64 * 0.98).saturating_sub(1);
    v.get(k).copied().filter(|m| *m > 0.0).unwrap_or(1.0)
}

/// Per instrument: residual maps of each direction before and after, error vectors.
pub fn instruments(r: &Report) -> String {
    let d = r.before;
    let mut groups: Vec<_> = d.groups.iter().filter(|g| g.rows >= 8).collect();
    // worst first, the TCP directions before the drives' incompatibility
    groups.sort_by(|a, b| {
        let compat = |g: &rpkm_core::diagnose::GroupRms| g.direction.starts_with("compat");
        compat(a)
            .cmp(&compat(b))
            .then(b.chi2_per_row.total_cmp(&a.chi2_per_row))
    });
    let mut order: Vec<&str> = Vec::new();
    for g in &groups {
        if !order.contains(&g.instrument.as_str()) {
            order.push(&g.instrument);
        }
    }
    let mut o = String::new();
    for inst in order {
        let _ = write!(
            o,
            "<section class=\"instrument\"><h2>{}: residual over the workspace</h2>",
            escape(inst)
        );
        let view = View::around(
            d.points
                .iter()
                .filter(|p| p.instrument == inst)
                .map(|p| (p.x, p.y)),
        );
        for g in groups.iter().filter(|g| g.instrument == inst) {
            o.push_str(&direction_maps(r, inst, &g.direction, view));
        }
        o.push_str(&vector_maps(r, inst, view));
        o.push_str("</section>");
    }
    o
}

/// The machine as a thumbnail with a map's view in it (empty where the reset pose cannot be
/// solved).
fn thumbnail(c: &Campaign, view: View) -> String {
    machine_at_reset(c).map_or(String::new(), |(m, _)| m.thumbnail(96.0, (view.x, view.y)))
}

/// Before and after of one direction, one colour scale.
fn direction_maps(r: &Report, inst: &str, dir: &str, view: View) -> String {
    let unit = if dir.starts_with("psi") {
        "µrad"
    } else if dir.starts_with('f') {
        "N"
    } else {
        "µm"
    };
    let before = of(r.before, inst, dir);
    let after = r.after.map(|a| of(a, inst, dir));
    let vmax = maps::round_up(p98(before
        .clone()
        .chain(after.clone().into_iter().flatten())
        .map(|p| p.value)));
    let rms = |pts: &mut dyn Iterator<Item = &ResidualPoint>| {
        let (n, s) = pts.fold((0usize, 0.0), |(n, s), p| (n + 1, s + p.value * p.value));
        (s / n.max(1) as f64).sqrt()
    };
    let mut o = format!(
        "<h3>{} {}: RMS {:.2} {unit}",
        escape(inst),
        escape(dir),
        rms(&mut before.clone())
    );
    if let Some(a) = after.clone() {
        let _ = write!(o, " → {:.2} {unit}", rms(&mut a.clone()));
    }
    o.push_str("</h3><div class=\"row pair\">");
    let b = maps::heat_map("before", &map_points(before), view, vmax, unit);
    o.push_str(&figure(&b, &Report::stage_of(r.before).model));
    if let (Some(a), Some(ad)) = (after, r.after) {
        let m = maps::heat_map("after", &map_points(a), view, vmax, unit);
        o.push_str(&figure(&m, &Report::stage_of(ad).model));
    }
    let thumb = thumbnail(r.campaign, view);
    let side = format!(
        "<div class=\"side\">{}{thumb}</div>",
        maps::colour_bar(vmax, unit)
    );
    o.push_str(&figure(
        &side,
        "model − measured; right: where the maps lie",
    ));
    o.push_str("</div>");
    o
}

/// The arrows of one instrument in `d`, each titled with its line, pose, error and the σ of
/// its rows along and across the beam (x and y for the grid encoder).
fn arrows(d: &ModelDiagnosis, inst: &str) -> Vec<Arrow> {
    let mut sigma: std::collections::BTreeMap<usize, [f64; 2]> =
        std::collections::BTreeMap::default();
    for p in d.points.iter().filter(|p| p.instrument == inst) {
        let k = match p.direction.as_str() {
            "along" => 0,
            "across" => 1,
            _ => continue,
        };
        sigma.entry(p.pose).or_insert([f64::NAN; 2])[k] = p.sigma;
    }
    d.error_vectors
        .iter()
        .filter(|v| v.instrument == inst)
        .map(|v| {
            let [along, across] = sigma.get(&v.pose).copied().unwrap_or([f64::NAN; 2]);
            Arrow {
                x: v.x,
                y: v.y,
                dx_um: um_from_mm(v.dx),
                dy_um: um_from_mm(v.dy),
                hover: format!(
                    "line {}: x {:.1}, y {:.1} mm: error ({:.2}, {:.2}) µm, |e| {:.2} µm (σ {along:.2} along, {across:.2} across), setup {}",
                    v.line,
                    v.x,
                    v.y,
                    um_from_mm(v.dx),
                    um_from_mm(v.dy),
                    um_from_mm(v.dx).hypot(um_from_mm(v.dy)),
                    v.setup
                ),
            }
        })
        .collect()
}

/// Error vectors of a 2-D instrument before and after, one arrow scale.
fn vector_maps(r: &Report, inst: &str, view: View) -> String {
    let before = arrows(r.before, inst);
    if before.is_empty() {
        return match &r.before.error_vectors_missing {
            Some(why) if matches!(inst, "lt" | "kgm") => {
                format!("<p class=\"muted\">No error vectors: {}</p>", escape(why))
            }
            _ => String::new(),
        };
    }
    let after = r.after.map_or(Vec::new(), |a| arrows(a, inst));
    let size = p98(before.iter().chain(&after).map(|a| a.dx_um.hypot(a.dy_um)));
    // the largest arrow spans about a grid step of the map
    let um_per_px = size / 32.0;
    let reference = maps::round_length(0.8 * size);
    let mut resets: Vec<(f64, f64)> = r
        .before
        .error_vectors
        .iter()
        .filter(|v| v.instrument == inst)
        .map(|v| (v.reset_x, v.reset_y))
        .collect();
    resets.dedup();
    let rms = |a: &[Arrow]| {
        let s: f64 = a.iter().map(|a| a.dx_um.powi(2) + a.dy_um.powi(2)).sum();
        (s / a.len().max(1) as f64).sqrt()
    };
    let mut o = format!(
        "<h3>{} error vectors: the model's TCP displacement from the reset pose minus the instrument's, RMS {:.1} µm",
        escape(inst),
        rms(&before)
    );
    if r.after.is_some() {
        let _ = write!(o, " → {:.1} µm", rms(&after));
    }
    o.push_str("</h3><div class=\"row pair\">");
    let b = maps::quiver("before", &before, &resets, view, um_per_px, reference);
    o.push_str(&figure(&b, &Report::stage_of(r.before).model));
    if let Some(ad) = r.after {
        let a = maps::quiver("after", &after, &resets, view, um_per_px, reference);
        o.push_str(&figure(
            &a,
            &format!(
                "{}: one arrow scale with before",
                Report::stage_of(ad).model
            ),
        ));
    }
    o.push_str(&figure(
        &thumbnail(r.campaign, view),
        "where the maps lie in the machine",
    ));
    o.push_str("</div>");
    o
}

/// Values of a dictionary term at every pose: a covariate (or one derived from the pose
/// sequence), a drive force, time, or a workspace polynomial.
fn feature(c: &Campaign, name: &str) -> Option<Vec<f64>> {
    if let Some(v) = c.covariate(name) {
        return Some(v.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect());
    }
    let tcp = nominal_tcp(c);
    let f = |k: usize| c.poses.iter().map(|p| p.f[k]).collect();
    match name {
        "t" => Some(c.poses.iter().map(|p| p.t).collect()),
        "f1" => Some(f(0)),
        "f2" => Some(f(1)),
        "f3" => Some(f(2)),
        "f4" => Some(f(3)),
        "x" => Some(tcp.iter().map(|p| p.0).collect()),
        "y" => Some(tcp.iter().map(|p| p.1).collect()),
        "x^2" => Some(tcp.iter().map(|p| p.0 * p.0).collect()),
        "x*y" => Some(tcp.iter().map(|p| p.0 * p.1).collect()),
        "y^2" => Some(tcp.iter().map(|p| p.1 * p.1).collect()),
        _ => None,
    }
}

/// A term of a few distinct values (a direction of motion: ±1) spread into strips, each
/// point shifted by a fixed fraction of the span (golden-ratio sequence over the pose index:
/// the same page every run), so that the points do not hide each other.
fn spread(values: &[f64]) -> Vec<f64> {
    let mut distinct: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    if distinct.len() > 3 {
        return values.to_vec();
    }
    let (lo, hi) = plot::range(distinct.iter().copied(), 0.0);
    let width = 0.25 * (hi - lo).max(1e-9);
    values
        .iter()
        .enumerate()
        .map(|(i, v)| v + width * ((i as f64 * 0.618_034).fract() - 0.5))
        .collect()
}

/// Residual of one direction against a term, before and after.
fn against_term(r: &Report, inst: &str, dir: &str, term: &str, values: &[f64]) -> String {
    let at = spread(values);
    let series = |d: &ModelDiagnosis, name: String| Series {
        name,
        markers: of(d, inst, dir)
            .map(|p| Marker {
                x: at.get(p.pose).copied().unwrap_or(f64::NAN),
                y: p.value,
                hover: format!(
                    "line {}: x {:.1}, y {:.1} mm, {term} {:.4}: {:.2} (σ {:.2})",
                    p.line,
                    p.x,
                    p.y,
                    values.get(p.pose).copied().unwrap_or(f64::NAN),
                    p.value,
                    p.sigma
                ),
            })
            .collect(),
    };
    let mut all = vec![series(r.before, "before".to_owned())];
    if let Some(a) = r.after {
        all.push(series(a, "after".to_owned()));
    }
    let svg = plot::scatter(
        &format!("{inst} {dir} against {term}"),
        term,
        "residual (µm; µrad for ψ)",
        &all,
    );
    figure(
        &svg,
        &format!("Each point a row of the campaign; {term} from the file or the pose sequence."),
    )
}

/// Residual against time and against the term the verdict points at.
pub fn against(r: &Report) -> String {
    let d = r.before;
    let pointer = d.unexplained.as_ref().or(d.structure.pointer.as_ref());
    let (inst, dir, term) = match pointer {
        Some(p) => (p.instrument.clone(), p.direction.clone(), p.feature.clone()),
        None => match d
            .groups
            .iter()
            .max_by(|a, b| a.chi2_per_row.total_cmp(&b.chi2_per_row))
        {
            Some(g) => (g.instrument.clone(), g.direction.clone(), "t".to_owned()),
            None => return String::new(),
        },
    };
    let mut o = format!(
        "<section id=\"against\"><h2>Against time and against what the residual follows</h2><p>{}</p><div class=\"row\">",
        escape(&pointer.map_or("The direction with the largest χ² per row.".to_owned(), rpkm_nodes::words::follows))
    );
    let times: Vec<f64> = r.campaign.poses.iter().map(|p| p.t).collect();
    o.push_str(&against_term(r, &inst, &dir, "t", &times));
    if term != "t" {
        if let Some(values) = feature(r.campaign, &term) {
            o.push_str(&against_term(r, &inst, &dir, &term, &values));
        }
    }
    o.push_str("</div></section>");
    o
}

/// The effects tried: the table and what each explains.
pub fn effects(r: &Report) -> String {
    let d = r.before;
    let mut o = String::from("<section id=\"effects\"><h2>Effects tried</h2><table><tr><th>effect</th><th>significant</th><th>relevant</th><th>explained</th><th>F</th><th>p</th><th>held-out after µm</th><th style=\"text-align:left\">evidence</th></tr>");
    for c in &d.candidates {
        // a written effect shows what it is: its expressions
        let name = match r.written.iter().find(|w| w.0 == c.effect) {
            Some((_, exprs)) => format!("{}<br><code>{}</code>", escape(&c.effect), escape(exprs)),
            None => escape(&c.effect),
        };
        let _ = write!(
            o,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{:.0} %</td><td>{:.3e}</td><td>{:.1e}</td><td>{}</td><td style=\"text-align:left\">{}</td></tr>",
            name,
            c.significant,
            c.relevant,
            100.0 * c.explained_fraction,
            c.f_statistic,
            c.p_value,
            um(c.val_rms_after.map(um_from_mm)),
            escape(&rpkm_nodes::words::evidence(c))
        );
    }
    o.push_str("</table>");
    for s in &d.skipped {
        let _ = write!(
            o,
            "<p class=\"muted\">{} not tried: {}</p>",
            escape(&s.effect),
            escape(&s.reason)
        );
    }
    if !d.candidates.is_empty() {
        let names: Vec<String> = d.candidates.iter().map(|c| c.effect.clone()).collect();
        let chart = plot::bar_chart(
            "Residual above the noise each effect explains",
            "explained (%)",
            &names,
            &[(
                "explained".to_owned(),
                d.candidates
                    .iter()
                    .map(|c| 100.0 * c.explained_fraction)
                    .collect(),
            )],
            &BarOptions::default(),
        );
        o.push_str(&figure(
            &chart,
            "Nested F-test per effect; ranked by BIC gain.",
        ));
    }
    o.push_str("</section>");
    o
}
