//! Maps over the workspace: residual heat map and residual vectors (quiver).

use super::chart::{legend_width, title, x_axis, y_axis, Area, LABEL_SIZE, TICK_SIZE};
use super::scale::{finite_range, label, nice_step, Scale};
use super::svg::{escape, num, Anchor, Svg};

/// Diverging colormap (ColorBrewer RdBu, blue negative, red positive) at `t` ∈ [−1, 1].
pub(super) fn diverging(t: f64) -> String {
    const STOPS: [(f64, [f64; 3]); 7] = [
        (-1.0, [33.0, 102.0, 172.0]),
        (-0.6, [103.0, 169.0, 207.0]),
        (-0.25, [209.0, 229.0, 240.0]),
        (0.0, [247.0, 247.0, 247.0]),
        (0.25, [253.0, 219.0, 199.0]),
        (0.6, [239.0, 138.0, 98.0]),
        (1.0, [178.0, 24.0, 43.0]),
    ];
    let t = if t.is_finite() {
        t.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let mut rgb = [247.0; 3];
    for w in STOPS.windows(2) {
        let (&(a, ca), &(b, cb)) = match w {
            [p, q] => (p, q),
            _ => continue,
        };
        if t >= a && t <= b {
            let u = (t - a) / (b - a);
            for (k, c) in rgb.iter_mut().enumerate() {
                *c = ca[k] + u * (cb[k] - ca[k]);
            }
            break;
        }
    }
    format!(
        "#{:02x}{:02x}{:02x}",
        rgb[0].round() as u8,
        rgb[1].round() as u8,
        rgb[2].round() as u8
    )
}

/// Smallest positive gap between distinct finite values (the grid spacing), if any.
fn spacing(values: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = values.filter(|v| v.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.windows(2)
        .filter_map(|w| match w {
            [a, b] => Some(b - a),
            _ => None,
        })
        .filter(|d| *d > 0.0)
        .min_by(f64::total_cmp)
}

/// The frame of a workspace map: size, plot area and the x, y scales.
fn workspace_frame(
    xs: impl Iterator<Item = f64> + Clone,
    ys: impl Iterator<Item = f64> + Clone,
    right: f64,
) -> (f64, f64, Area, Scale, Scale) {
    let width = 82.0 + 420.0 + right;
    let height = 620.0;
    let area = Area {
        x0: 82.0,
        y0: 50.0,
        x1: 82.0 + 420.0,
        y1: height - 62.0,
    };
    let sx = Scale::linear(xs, false, 0.06, area.x0, area.x1);
    let sy = Scale::linear(ys, false, 0.04, area.y1, area.y0);
    (width, height, area, sx, sy)
}

/// Residual map over the workspace: one cell per point (x, y in mm), coloured by `value`
/// on a diverging colormap centred at 0 (blue negative, white 0, red positive), symmetric
/// about 0, with a colour bar labelled `value_label`. Cells are sized by the grid spacing
/// (the smallest gap between distinct x, and y, coordinates); points with a non-finite
/// position are skipped, non-finite values drawn grey.
pub fn heat_map(title_text: &str, points: &[(f64, f64, f64)], value_label: &str) -> String {
    let shown: Vec<(f64, f64, f64)> = points
        .iter()
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let right = 140.0;
    let (width, height, area, sx, sy) =
        workspace_frame(shown.iter().map(|p| p.0), shown.iter().map(|p| p.1), right);
    let (lo, hi) = finite_range(shown.iter().map(|p| p.2));
    let peak = lo.abs().max(hi.abs());
    let peak = if peak.is_finite() && peak > 0.0 {
        peak
    } else {
        1.0
    };
    let step = nice_step(2.0 * peak, 6);
    let m = ((peak / step).ceil() * step).max(step);

    let mut svg = Svg::new(width, height);
    title(&mut svg, width, title_text);
    y_axis(&mut svg, &sy, area, "y (mm)");
    x_axis(&mut svg, &sx, area, "x (mm)");
    let px_step = |s: &Scale, d: Option<f64>, fallback: f64, max: f64| {
        d.and_then(|d| Some((s.px(d)? - s.px(0.0)?).abs()))
            .map_or(fallback, |w| w.clamp(4.0, max))
    };
    let w = px_step(&sx, spacing(shown.iter().map(|p| p.0)), 10.0, 60.0);
    let h = px_step(&sy, spacing(shown.iter().map(|p| p.1)), 10.0, 60.0);
    for &(x, y, v) in &shown {
        let (Some(cx), Some(cy)) = (sx.px(x), sy.px(y)) else {
            continue;
        };
        let fill = if v.is_finite() {
            diverging(v / m)
        } else {
            "#bdbdbd".to_owned()
        };
        svg.raw(&format!(
            r##"<rect class="cell" x="{}" y="{}" width="{}" height="{}" fill="{}" stroke="#ffffff" stroke-width="0.5"><title>{}</title></rect>"##,
            num(cx - w / 2.0),
            num(cy - h / 2.0),
            num(w),
            num(h),
            fill,
            escape(&format!("x = {x} mm, y = {y} mm: {v}"))
        ));
    }
    // Colour bar.
    let bx = area.x1 + 24.0;
    let (top, bottom) = (area.y0 + 10.0, area.y1 - 10.0);
    let n = 64;
    let dh = (bottom - top) / n as f64;
    for k in 0..n {
        let t = 1.0 - (k as f64 + 0.5) / n as f64 * 2.0;
        svg.rect(bx, top + k as f64 * dh, 18.0, dh + 0.5, &diverging(t), "");
    }
    svg.rect(bx, top, 18.0, bottom - top, "none", r##"stroke="#444444""##);
    let ticks = (2.0 * m / step).round() as i64;
    for k in 0..=ticks.clamp(0, 20) {
        let v = -m + k as f64 * step;
        let y = bottom - (v + m) / (2.0 * m) * (bottom - top);
        svg.line(bx + 18.0, y, bx + 23.0, y, "#444444", 1.0);
        svg.text_markup(
            bx + 26.0,
            y + 4.0,
            TICK_SIZE,
            Anchor::Start,
            &label(v, step),
            0.0,
            "",
        );
    }
    svg.text(
        width - 18.0,
        (top + bottom) / 2.0,
        LABEL_SIZE,
        Anchor::Middle,
        value_label,
        -90.0,
    );
    svg.finish()
}

/// Residual vectors over the workspace: an arrow (dx, dy) at each point (x, y in mm). The
/// arrows share one scale, chosen so that the longest is about one grid spacing, shown by a
/// reference arrow labelled with its length and `scale_label` (the unit of dx, dy, e.g.
/// "µm"). Points with a non-finite position or vector are skipped.
pub fn quiver(title_text: &str, points: &[(f64, f64, f64, f64)], scale_label: &str) -> String {
    let shown: Vec<(f64, f64, f64, f64)> = points
        .iter()
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite() && p.3.is_finite())
        .collect();
    let right = legend_width(std::iter::once(scale_label.chars().count() + 10)).max(120.0);
    let (width, height, area, sx, sy) =
        workspace_frame(shown.iter().map(|p| p.0), shown.iter().map(|p| p.1), right);
    let gap = |s: &Scale, d: Option<f64>| d.and_then(|d| Some((s.px(d)? - s.px(0.0)?).abs()));
    let cell = match (
        gap(&sx, spacing(shown.iter().map(|p| p.0))),
        gap(&sy, spacing(shown.iter().map(|p| p.1))),
    ) {
        (Some(a), Some(b)) => a.min(b),
        (Some(a), None) | (None, Some(a)) => a,
        (None, None) => 40.0,
    }
    .clamp(12.0, 60.0);
    let longest = shown.iter().map(|p| p.2.hypot(p.3)).fold(0.0f64, f64::max);
    let gain = if longest > 0.0 {
        cell * 1.1 / longest
    } else {
        0.0
    };

    let mut svg = Svg::new(width, height);
    title(&mut svg, width, title_text);
    y_axis(&mut svg, &sy, area, "y (mm)");
    x_axis(&mut svg, &sx, area, "x (mm)");
    for &(x, y, dx, dy) in &shown {
        let (Some(px), Some(py)) = (sx.px(x), sy.px(y)) else {
            continue;
        };
        svg.circle(px, py, 1.8, "#555555", "");
        arrow(&mut svg, px, py, dx * gain, -dy * gain, "#c0392b");
    }
    // Reference arrow.
    let bx = area.x1 + 16.0;
    let by = area.y0 + 20.0;
    if longest > 0.0 {
        let step = nice_step(longest, 1);
        let reference = if step > longest { step / 2.0 } else { step };
        let len = reference * gain;
        arrow(&mut svg, bx, by, len, 0.0, "#c0392b");
        svg.text(
            bx,
            by + 20.0,
            TICK_SIZE,
            Anchor::Start,
            &format!("{} {scale_label}", label(reference, reference / 10.0)),
            0.0,
        );
    }
    svg.finish()
}

/// An arrow from (x, y) by (dx, dy) px; a dot when it is too short to show a head.
fn arrow(svg: &mut Svg, x: f64, y: f64, dx: f64, dy: f64, stroke: &str) {
    let len = dx.hypot(dy);
    if !(len.is_finite() && len >= 1.0) {
        return;
    }
    let (ux, uy) = (dx / len, dy / len);
    let head = (len * 0.35).min(7.0);
    let (tx, ty) = (x + dx, y + dy);
    let (bx, by) = (tx - ux * head, ty - uy * head);
    svg.line(x, y, bx, by, stroke, 1.4);
    let half = head * 0.5;
    svg.polygon(
        &[
            (tx, ty),
            (bx - uy * half, by + ux * half),
            (bx + uy * half, by - ux * half),
        ],
        stroke,
        "",
    );
}
