//! Maps over the workspace: residual heat maps (an interpolated field under the measured
//! poses, on a colour scale given by the caller so that before and after share it), error
//! vectors (an arrow per pose, with a scale arrow), and the machine with the campaign's poses.

use super::axes::{plain, Axes};
use super::machine::Machine;
use super::{color, escape, with_overlay, Frame};
use std::fmt::Write as _;

/// A residual at a pose, with what its tooltip says.
#[derive(Clone, Debug)]
pub struct MapPoint {
    pub x: f64,
    pub y: f64,
    pub value: f64,
    pub sigma: f64,
    pub line: usize,
}

/// An error vector at a pose (µm), with its tooltip.
#[derive(Clone, Debug)]
pub struct Arrow {
    pub x: f64,
    pub y: f64,
    pub dx_um: f64,
    pub dy_um: f64,
    pub hover: String,
}

/// The part of the workspace a map shows (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub x: (f64, f64),
    pub y: (f64, f64),
}

impl View {
    /// The poses' extent with a margin (a tenth of the span, at least 25 mm).
    pub fn around(points: impl IntoIterator<Item = (f64, f64)> + Clone) -> View {
        let pad = |(lo, hi): (f64, f64)| {
            let m = (0.1 * (hi - lo)).max(25.0);
            (lo - m, hi + m)
        };
        View {
            x: pad(super::range(points.clone().into_iter().map(|p| p.0), 0.0)),
            y: pad(super::range(points.into_iter().map(|p| p.1), 0.0)),
        }
    }
}

/// Levels of the colour scale on each side of zero: the map reads in steps of vmax / LEVELS.
const LEVELS: i32 = 8;
/// Side of a heat-map cell, px.
const CELL: f64 = 6.0;

/// Diverging colour of `v` on a scale symmetric about zero (ColorBrewer RdBu: blue negative,
/// white zero, red positive), quantised to [`LEVELS`] steps per side.
pub fn diverging(v: f64, vmax: f64) -> String {
    const STOPS: [(f64, [f64; 3]); 7] = [
        (-1.0, [33.0, 102.0, 172.0]),
        (-0.6, [103.0, 169.0, 207.0]),
        (-0.25, [209.0, 229.0, 240.0]),
        (0.0, [247.0, 247.0, 247.0]),
        (0.25, [253.0, 219.0, 199.0]),
        (0.6, [239.0, 138.0, 98.0]),
        (1.0, [178.0, 24.0, 43.0]),
    ];
    let level = (v / vmax * f64::from(LEVELS))
        .round()
        .clamp(f64::from(-LEVELS), f64::from(LEVELS));
    let t = if level.is_finite() {
        level / f64::from(LEVELS)
    } else {
        0.0
    };
    let k = STOPS
        .iter()
        .rposition(|s| s.0 <= t)
        .unwrap_or(0)
        .min(STOPS.len() - 2);
    let ((t0, c0), (t1, c1)) = (STOPS[k], STOPS[k + 1]);
    let w = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
    let c: Vec<u8> = (0..3)
        .map(|i| rpkm_core::convert::round_u8(c0[i] + w * (c1[i] - c0[i])))
        .collect();
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// The frame of a workspace map.
fn map_axes(caption: &str, view: View) -> (String, Frame) {
    Axes {
        width: 330,
        height: 440,
        caption,
        x_label: "x (mm)",
        y_label: "y (mm)",
        x: view.x,
        y: view.y,
        y_label_area: 48,
        x_ticks: Some(plain),
        y_ticks: Some(plain),
    }
    .draw()
}

/// Residual heat map: each cell of the plotting area takes the inverse-distance weighted
/// mean of the residuals near it (within 2.2 median neighbour distances, on screen, so that a
/// map of a few grid lines is filled between them and a cluster stays a blob), coloured on
/// the scale ±`vmax`; the poses on top, each with its file line, pose, value and σ.
pub fn heat_map(caption: &str, points: &[MapPoint], view: View, vmax: f64, unit: &str) -> String {
    let (svg, f) = map_axes(caption, view);
    let pts: Vec<(f64, f64, f64)> = points
        .iter()
        .filter(|p| p.x.is_finite() && p.y.is_finite() && p.value.is_finite())
        .map(|p| {
            let (x, y) = f.at(p.x, p.y);
            (x, y, p.value)
        })
        .collect();
    let reach = 2.2 * median_neighbour_distance(&pts).max(6.0);
    let mut o = String::from("<g class=\"heat\">");
    let (nx, ny) = (
        rpkm_core::convert::ceil_count((f.px.1 - f.px.0) / CELL),
        rpkm_core::convert::ceil_count((f.py.0 - f.py.1) / CELL),
    );
    for j in 0..ny {
        let cy = f.py.1 + (j as f64 + 0.5) * CELL;
        // a run of cells of one colour is one rectangle
        let mut run: Option<(usize, String)> = None;
        for i in 0..=nx {
            let colour = (i < nx)
                .then(|| idw(&pts, f.px.0 + (i as f64 + 0.5) * CELL, cy, reach))
                .flatten()
                .map(|v| diverging(v, vmax));
            if run.as_ref().map(|r| Some(&r.1)) != Some(colour.as_ref()) {
                if let Some((start, c)) = run.take() {
                    // cells stop at the plotting area's edges
                    let (x, y) = (f.px.0 + start as f64 * CELL, cy - 0.5 * CELL);
                    let _ = write!(
                        o,
                        "<rect x=\"{x:.1}\" y=\"{y:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{c}\"/>",
                        ((i - start) as f64 * CELL + 0.3).min(f.px.1 - x),
                        (CELL + 0.3).min(f.py.0 - y)
                    );
                }
                run = colour.map(|c| (i, c));
            }
        }
    }
    o.push_str("</g><g class=\"poses\" stroke=\"#333\" stroke-width=\"0.6\">");
    for p in points {
        if !(p.x.is_finite() && p.y.is_finite() && p.value.is_finite()) {
            continue;
        }
        let (x, y) = f.at(p.x, p.y);
        let _ = write!(
            o,
            "<circle class=\"point\" cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"2.6\" fill=\"{}\"><title>line {}: x {:.1}, y {:.1} mm: {:.2} {unit} (σ {:.2}, {:.1}σ)</title></circle>",
            diverging(p.value, vmax),
            p.line,
            p.x,
            p.y,
            p.value,
            p.sigma,
            p.value / p.sigma
        );
    }
    o.push_str("</g>");
    with_overlay(svg, &o)
}

/// Inverse-distance weighted mean of the values within `reach` px of (x, y), if any.
fn idw(pts: &[(f64, f64, f64)], x: f64, y: f64, reach: f64) -> Option<f64> {
    let (mut sw, mut swv) = (0.0, 0.0);
    for &(px, py, v) in pts {
        let d2 = (px - x).powi(2) + (py - y).powi(2);
        if d2 <= reach * reach {
            let w = 1.0 / (d2 + 4.0);
            sw += w;
            swv += w * v;
        }
    }
    (sw > 0.0).then(|| swv / sw)
}

/// Median distance of each point to its nearest distinct neighbour (px).
fn median_neighbour_distance(pts: &[(f64, f64, f64)]) -> f64 {
    let mut d: Vec<f64> = pts
        .iter()
        .map(|a| {
            pts.iter()
                .map(|b| ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt())
                .filter(|d| *d > 0.5)
                .fold(f64::INFINITY, f64::min)
        })
        .filter(|d| d.is_finite())
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied().unwrap_or(20.0)
}

/// The colour bar of a pair of maps: ±`vmax` in [`LEVELS`] steps per side.
pub fn colour_bar(vmax: f64, unit: &str) -> String {
    let (top, h, w) = (40.0, 340.0, 22.0);
    let step = h / f64::from(2 * LEVELS + 1);
    let mut o = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"96\" height=\"440\" viewBox=\"0 0 96 440\" font-family=\"sans-serif\" font-size=\"11\"><rect width=\"96\" height=\"440\" fill=\"#fff\"/><text x=\"4\" y=\"24\">{}</text>",
        escape(unit)
    );
    for k in -LEVELS..=LEVELS {
        let v = vmax * f64::from(k) / f64::from(LEVELS);
        let y = top + f64::from(LEVELS - k) * step;
        let _ = write!(
            o,
            "<rect x=\"6\" y=\"{y:.1}\" width=\"{w}\" height=\"{:.1}\" fill=\"{}\"><title>{v:.2} {}</title></rect>",
            step + 0.3,
            diverging(v, vmax),
            escape(unit)
        );
        if k % 4 == 0 {
            let _ = write!(
                o,
                "<text x=\"32\" y=\"{:.1}\" dy=\"0.35em\">{}</text>",
                y + step / 2.0,
                plain(&v)
            );
        }
    }
    o.push_str("</svg>");
    o
}

/// A round reference length (1, 2 or 5 times a power of ten) near `v`.
pub fn round_length(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .min_by(|a, b| (a - v).abs().total_cmp(&(b - v).abs()))
        .unwrap_or(p)
}

/// The smallest round number (1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a power of ten) not
/// below `v`: the end of a colour scale whose ticks read cleanly.
pub fn round_up(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(v.log10().floor());
    [1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|m| *m >= v * (1.0 - 1e-12))
        .unwrap_or(10.0 * p)
}

/// Error-vector map: an arrow per pose, `um_per_px` µm per pixel in both directions (the
/// pair before/after shares it), the reset poses ringed, a scale arrow of `reference_um`.
pub fn quiver(
    caption: &str,
    arrows: &[Arrow],
    resets: &[(f64, f64)],
    view: View,
    um_per_px: f64,
    reference_um: f64,
) -> String {
    let (svg, f) = map_axes(caption, view);
    let mut o =
        String::from("<g class=\"arrows\" stroke=\"#1f3b57\" fill=\"none\" stroke-width=\"1.3\">");
    for a in arrows {
        if !(a.x.is_finite() && a.y.is_finite() && a.dx_um.is_finite() && a.dy_um.is_finite()) {
            continue;
        }
        let (x, y) = f.at(a.x, a.y);
        let _ = write!(
            o,
            "<g class=\"arrow\"><title>{}</title><circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"1.6\" fill=\"#1f3b57\"/>{}</g>",
            escape(&a.hover),
            arrow_path(x, y, a.dx_um / um_per_px, -a.dy_um / um_per_px)
        );
    }
    o.push_str("</g>");
    for &(rx, ry) in resets {
        let (x, y) = f.at(rx, ry);
        let _ = write!(
            o,
            "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"7\" fill=\"none\" stroke=\"{}\" stroke-width=\"2\"><title>reset pose x {rx:.1}, y {ry:.1} mm (errors are relative to it)</title></circle>",
            color(2)
        );
    }
    let (sx, sy) = (f.px.0 + 10.0, f.py.0 - 14.0);
    let _ = write!(
        o,
        "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"24\" fill=\"#fff\" fill-opacity=\"0.85\"/><g stroke=\"#b2182b\" stroke-width=\"1.6\" fill=\"none\">{}</g><text x=\"{sx:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"11\" fill=\"#b2182b\">{} µm</text>",
        sx - 4.0,
        sy - 18.0,
        reference_um / um_per_px + 50.0,
        arrow_path(sx, sy, reference_um / um_per_px, 0.0),
        sy - 5.0,
        plain(&reference_um)
    );
    with_overlay(svg, &o)
}

/// An arrow from (x, y) by (dx, dy) px with a head of two strokes.
fn arrow_path(x: f64, y: f64, dx: f64, dy: f64) -> String {
    let len = (dx * dx + dy * dy).sqrt();
    if len < 0.5 {
        return String::new();
    }
    let (ux, uy) = (dx / len, dy / len);
    let head = (0.35 * len).min(6.0);
    let (ex, ey) = (x + dx, y + dy);
    let side = |s: f64| {
        let (c, n) = (0.906, 0.423 * s); // cos, sin of 25°
        (ex - head * (c * ux - n * uy), ey - head * (n * ux + c * uy))
    };
    let (l, r) = (side(1.0), side(-1.0));
    format!(
        "<path d=\"M{x:.1},{y:.1}L{ex:.1},{ey:.1}M{:.1},{:.1}L{ex:.1},{ey:.1}L{:.1},{:.1}\"/>",
        l.0, l.1, r.0, r.1
    )
}

/// The machine at true scale (equal mm per pixel on both axes) with the campaign's poses as
/// dots per instrument and the maps' view as a dashed rectangle.
pub fn machine_figure(
    caption: &str,
    machine: &Machine,
    poses: &[(f64, f64, String)],
    view: View,
) -> String {
    let ((x0, x1), (y0, y1)) = machine.extent();
    let (mut x, mut y) = ((x0 - 120.0, x1 + 120.0), (y0 - 120.0, y1 + 120.0));
    let height = rpkm_core::convert::round_u32(520.0 * (y.1 - y.0) / (x.1 - x.0) + 90.0);
    let mut axes = Axes {
        width: 590,
        height,
        caption,
        x_label: "x (mm)",
        y_label: "y (mm)",
        x,
        y,
        y_label_area: 52,
        x_ticks: Some(plain),
        y_ticks: Some(plain),
    };
    // true scale: the axis with more pixels per mm is widened until both have the same
    let (sx, sy) = axes.draw().1.scale();
    if sx > sy {
        let grow = (x.1 - x.0) * (sx / sy - 1.0) / 2.0;
        x = (x.0 - grow, x.1 + grow);
    } else {
        let grow = (y.1 - y.0) * (sy / sx - 1.0) / 2.0;
        y = (y.0 - grow, y.1 + grow);
    }
    axes.x = x;
    axes.y = y;
    let (svg, f) = axes.draw();
    let mut o = machine.svg(&f);
    let (a, b) = (f.at(view.x.0, view.y.1), f.at(view.x.1, view.y.0));
    let _ = write!(
        o,
        "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"#b2182b\" stroke-dasharray=\"5 3\" stroke-width=\"1.5\"><title>the maps' view</title></rect>",
        a.0,
        a.1,
        b.0 - a.0,
        b.1 - a.1
    );
    let mut instruments: Vec<&str> = poses.iter().map(|p| p.2.as_str()).collect();
    instruments.dedup();
    instruments.sort_unstable();
    instruments.dedup();
    for (k, inst) in instruments.iter().enumerate() {
        let _ = write!(o, "<g fill=\"{}\" fill-opacity=\"0.8\">", color(k));
        for p in poses
            .iter()
            .filter(|p| p.2 == *inst && p.0.is_finite() && p.1.is_finite())
        {
            let (px, py) = f.at(p.0, p.1);
            let _ = write!(o, "<circle cx=\"{px:.1}\" cy=\"{py:.1}\" r=\"1.8\"/>");
        }
        let _ = write!(
            o,
            "</g><circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{}\"/><text x=\"{:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"12\">{} poses</text>",
            f.px.0 + 12.0,
            f.py.1 + 12.0 + 16.0 * k as f64,
            color(k),
            f.px.0 + 20.0,
            f.py.1 + 16.0 + 16.0 * k as f64,
            escape(inst)
        );
    }
    with_overlay(svg, &o)
}
