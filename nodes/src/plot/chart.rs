//! Bar and line charts, and the frame (title, axes, legend) every chart shares.

use super::scale::Scale;
use super::svg::{escape, num, Anchor, Svg};
use super::{color, BarOptions, LineOptions};

/// Font sizes.
pub(super) const TITLE_SIZE: f64 = 17.0;
pub(super) const LABEL_SIZE: f64 = 14.0;
pub(super) const TICK_SIZE: f64 = 12.0;

/// The plot area in px.
#[derive(Clone, Copy, Debug)]
pub(super) struct Area {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

/// Approximate width of `text` at `size` px (for layout).
pub(super) fn text_width(text: &str, size: f64) -> f64 {
    text.chars().count() as f64 * size * 0.6
}

/// The title, centred at the top.
pub(super) fn title(svg: &mut Svg, width: f64, title: &str) {
    svg.text_markup(
        width / 2.0,
        28.0,
        TITLE_SIZE,
        Anchor::Middle,
        &escape(title),
        0.0,
        r#"font-weight="bold""#,
    );
}

/// The y axis on the left of `area`: ticks, labels, horizontal grid lines, the axis label.
pub(super) fn y_axis(svg: &mut Svg, scale: &Scale, area: Area, label: &str) {
    for (v, text) in scale.ticks() {
        let Some(y) = scale.px(v) else { continue };
        svg.line(area.x0, y, area.x1, y, "#e6e6e6", 1.0);
        svg.line(area.x0 - 5.0, y, area.x0, y, "#444444", 1.0);
        svg.text_markup(
            area.x0 - 8.0,
            y + 4.0,
            TICK_SIZE,
            Anchor::End,
            &text,
            0.0,
            "",
        );
    }
    svg.line(area.x0, area.y0, area.x0, area.y1, "#444444", 1.0);
    svg.text(
        18.0,
        (area.y0 + area.y1) / 2.0,
        LABEL_SIZE,
        Anchor::Middle,
        label,
        -90.0,
    );
}

/// The x axis below `area`: ticks, labels, vertical grid lines, the axis label.
pub(super) fn x_axis(svg: &mut Svg, scale: &Scale, area: Area, label: &str) {
    for (v, text) in scale.ticks() {
        let Some(x) = scale.px(v) else { continue };
        svg.line(x, area.y0, x, area.y1, "#e6e6e6", 1.0);
        svg.line(x, area.y1, x, area.y1 + 5.0, "#444444", 1.0);
        svg.text_markup(x, area.y1 + 19.0, TICK_SIZE, Anchor::Middle, &text, 0.0, "");
    }
    svg.line(area.x0, area.y1, area.x1, area.y1, "#444444", 1.0);
    svg.text(
        (area.x0 + area.x1) / 2.0,
        area.y1 + 44.0,
        LABEL_SIZE,
        Anchor::Middle,
        label,
        0.0,
    );
}

/// How a legend entry is drawn.
#[derive(Clone, Copy)]
pub(super) enum Key {
    Swatch,
    Line,
    Marker,
    LineAndMarker,
}

/// A legend at (x, y) (top left), one entry per line.
pub(super) fn legend(svg: &mut Svg, x: f64, y: f64, entries: &[(&str, &str, Key)]) {
    for (i, (name, fill, key)) in entries.iter().enumerate() {
        let cy = y + 10.0 + i as f64 * 20.0;
        match key {
            Key::Swatch => svg.rect(x, cy - 6.0, 14.0, 12.0, fill, ""),
            Key::Line => svg.line(x, cy, x + 16.0, cy, fill, 2.0),
            Key::Marker => svg.circle(x + 8.0, cy, 3.5, fill, ""),
            Key::LineAndMarker => {
                svg.line(x, cy, x + 16.0, cy, fill, 2.0);
                svg.circle(x + 8.0, cy, 3.5, fill, "");
            }
        }
        svg.text(x + 22.0, cy + 4.5, TICK_SIZE, Anchor::Start, name, 0.0);
    }
}

/// Width of the right margin holding a legend of `names`.
pub(super) fn legend_width(names: impl Iterator<Item = usize>) -> f64 {
    let longest = names.max().unwrap_or(0) as f64;
    (longest * TICK_SIZE * 0.6 + 50.0).clamp(40.0, 320.0)
}

/// Grouped bars: one group per category, one bar per series in each group (sensitivity per
/// parameter and measurement direction; condition numbers with `opts.log_y`). A series with
/// fewer values than categories, and non-finite values (or values ≤ 0 on a log axis), give
/// empty bars; extra values are ignored. Every bar is a `<rect class="bar">`, so a chart has
/// exactly `categories.len() × series.len()` of them.
pub fn bar_chart(
    title_text: &str,
    y_label: &str,
    categories: &[String],
    series: &[(String, Vec<f64>)],
    opts: &BarOptions,
) -> String {
    let n_cat = categories.len();
    let n_ser = series.len();
    let longest = categories
        .iter()
        .map(|c| c.chars().count())
        .max()
        .unwrap_or(0);
    let group = ((n_ser as f64) * 9.0 + 10.0).max(26.0);
    let left = 82.0;
    let right = if n_ser > 0 {
        legend_width(series.iter().map(|(n, _)| n.chars().count()))
    } else {
        30.0
    };
    let width = (left + right + group * n_cat as f64).max(720.0);
    let plot_w = width - left - right;
    let group_px = if n_cat > 0 {
        plot_w / n_cat as f64
    } else {
        plot_w
    };
    let rotate = text_width(&"m".repeat(longest), TICK_SIZE) > group_px - 4.0;
    let label_room = if rotate {
        (text_width(&"m".repeat(longest), TICK_SIZE) * 0.75).min(160.0)
    } else {
        TICK_SIZE
    };
    let height = 420.0 + label_room;
    let area = Area {
        x0: left,
        y0: 50.0,
        x1: width - right,
        y1: height - 50.0 - label_room,
    };
    let values = series.iter().flat_map(|(_, v)| v.iter().copied());
    let scale = if opts.log_y {
        Scale::log(values, area.y1, area.y0)
    } else {
        Scale::linear(values, true, 0.05, area.y1, area.y0)
    };

    let mut svg = Svg::new(width, height);
    title(&mut svg, width, title_text);
    y_axis(&mut svg, &scale, area, y_label);
    let base = if scale.is_log() {
        area.y1
    } else {
        scale.px_clamped(0.0)
    };
    let inner = group_px * 0.8;
    let bar_w = if n_ser > 0 {
        inner / n_ser as f64
    } else {
        inner
    };
    for (c, category) in categories.iter().enumerate() {
        let gx = area.x0 + c as f64 * group_px + (group_px - inner) / 2.0;
        for (s, (name, vals)) in series.iter().enumerate() {
            let v = vals.get(c).copied().unwrap_or(f64::NAN);
            let x = gx + s as f64 * bar_w;
            let tip = format!("{category} / {name}: {v}");
            let top = scale.px(v).map(|p| p.clamp(area.y0, area.y1));
            let (y, h, class) = match top {
                Some(top) => (top.min(base), (top - base).abs(), "bar"),
                None => (base, 0.0, "bar missing"),
            };
            if top.is_none() {
                // Mark values that cannot be shown, so that a gap is not read as 0.
                let label_y = base - 4.0;
                svg.text_markup(
                    x + bar_w / 2.0 + 3.0,
                    label_y,
                    9.0,
                    Anchor::Start,
                    "n/a",
                    -90.0,
                    r##"fill-opacity="0.6""##,
                );
            }
            svg.raw(&format!(
                r#"<rect class="{class}" x="{}" y="{}" width="{}" height="{}" fill="{}"><title>{}</title></rect>"#,
                num(x),
                num(y),
                num((bar_w - 1.0).max(1.0)),
                num(h),
                color(s),
                escape(&tip)
            ));
        }
        let cx = area.x0 + (c as f64 + 0.5) * group_px;
        if rotate {
            svg.text(
                cx + 4.0,
                area.y1 + 14.0,
                TICK_SIZE,
                Anchor::End,
                category,
                -45.0,
            );
        } else {
            svg.text(cx, area.y1 + 18.0, TICK_SIZE, Anchor::Middle, category, 0.0);
        }
    }
    svg.line(area.x0, base, area.x1, base, "#444444", 1.0);
    let entries: Vec<(&str, &str, Key)> = series
        .iter()
        .enumerate()
        .map(|(i, (n, _))| (n.as_str(), color(i), Key::Swatch))
        .collect();
    legend(&mut svg, area.x1 + 16.0, area.y0, &entries);
    svg.finish()
}

/// Series of (x, y) points as lines and/or markers (`LineOptions::SCATTER` for residuals
/// against time or a covariate). Lines break at non-finite points, which are not drawn.
pub fn line_chart(
    title_text: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
    opts: &LineOptions,
) -> String {
    let right = if series.is_empty() {
        30.0
    } else {
        legend_width(series.iter().map(|(n, _)| n.chars().count()))
    };
    let width = 560.0 + 82.0 + right;
    let height = 440.0;
    let area = Area {
        x0: 82.0,
        y0: 50.0,
        x1: width - right,
        y1: height - 62.0,
    };
    let finite = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite();
    let points = || {
        series
            .iter()
            .flat_map(|(_, p)| p.iter().filter(|p| finite(p)))
    };
    let xs = Scale::linear(points().map(|p| p.0), false, 0.03, area.x0, area.x1);
    let ys = Scale::linear(points().map(|p| p.1), false, 0.05, area.y1, area.y0);

    let mut svg = Svg::new(width, height);
    title(&mut svg, width, title_text);
    y_axis(&mut svg, &ys, area, y_label);
    x_axis(&mut svg, &xs, area, x_label);
    for (i, (_, pts)) in series.iter().enumerate() {
        let px: Vec<Option<(f64, f64)>> = pts
            .iter()
            .map(|&(x, y)| Some((xs.px(x)?, ys.px(y)?)))
            .collect();
        if opts.lines {
            for run in px.split(Option::is_none) {
                let run: Vec<(f64, f64)> = run.iter().flatten().copied().collect();
                svg.polyline(&run, color(i), 1.8, "");
            }
        }
        if opts.markers || !opts.lines {
            for &(x, y) in px.iter().flatten() {
                svg.circle(x, y, 3.0, color(i), r#"fill-opacity="0.8""#);
            }
        }
    }
    let key = match (opts.lines, opts.markers) {
        (true, true) => Key::LineAndMarker,
        (true, false) => Key::Line,
        _ => Key::Marker,
    };
    let entries: Vec<(&str, &str, Key)> = series
        .iter()
        .enumerate()
        .map(|(i, (n, _))| (n.as_str(), color(i), key))
        .collect();
    legend(&mut svg, area.x1 + 16.0, area.y0, &entries);
    svg.finish()
}
