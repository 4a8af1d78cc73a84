//! A quantity over calendar time: points with their ±σ bars (each with a `<title>`: the
//! calibration, value, σ), a fitted line over the span it was fitted on, horizontal bounds
//! (a tolerance band) and a date with its ±σ (when the line crosses a bound). The x axis is
//! in days since 1970 and labelled with dates.

use super::axes::{plain, Axes};
use super::{color, escape, with_overlay};
use std::fmt::Write as _;

/// One point: day, value, its σ (0: no bar) and the tooltip.
#[derive(Clone, Debug)]
pub struct Dated {
    pub day: f64,
    pub value: f64,
    pub sigma: f64,
    pub hover: String,
}

/// A straight line from (day, value) to (day, value), and its legend.
#[derive(Clone, Debug)]
pub struct Line {
    pub from: (f64, f64),
    pub to: (f64, f64),
    pub name: String,
}

/// What a time chart shows.
#[derive(Clone, Debug, Default)]
pub struct TimeChart<'a> {
    pub title: &'a str,
    pub y_label: &'a str,
    pub points: Vec<Dated>,
    pub line: Option<Line>,
    /// Horizontal bounds (value, legend).
    pub bounds: Vec<(f64, String)>,
    /// A date and its σ, days (drawn as a vertical band and line), and its legend.
    pub date: Option<(f64, f64, String)>,
}

/// The tick label of a day count: its date.
#[expect(
    clippy::trivially_copy_pass_by_ref,
    reason = "a plotters label formatter: `&dyn Fn(&f64) -> String`"
)]
fn date_tick(day: &f64) -> String {
    let s = rpkm_core::convert::round_i64(day * 86_400.0);
    chrono::DateTime::from_timestamp(s, 0)
        .map_or_else(|| format!("{day:.0}"), |d| d.format("%Y-%m-%d").to_string())
}

/// The chart as an SVG document.
pub fn time_chart(c: &TimeChart) -> String {
    let days = c
        .points
        .iter()
        .map(|p| p.day)
        .chain(c.line.iter().flat_map(|l| [l.from.0, l.to.0]))
        .chain(c.date.iter().flat_map(|d| [d.0 - d.1, d.0 + d.1]));
    let values = c
        .points
        .iter()
        .flat_map(|p| [p.value - p.sigma, p.value + p.sigma])
        .chain(c.line.iter().flat_map(|l| [l.from.1, l.to.1]))
        .chain(c.bounds.iter().map(|b| b.0));
    let x = super::range(days, 0.04);
    let y = super::range(values, 0.08);
    let (svg, f) = Axes {
        width: 540,
        height: 340,
        caption: c.title,
        x_label: "date (UTC)",
        y_label: c.y_label,
        x,
        y,
        y_label_area: 56,
        x_ticks: Some(date_tick),
        y_ticks: Some(plain),
    }
    .draw();
    let mut o = String::new();
    let mut legend: Vec<(&str, String)> = Vec::new();
    for (value, name) in &c.bounds {
        let (a, b) = (f.at(x.0, *value), f.at(x.1, *value));
        let _ = write!(
            o,
            "<line class=\"bound\" x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#b2182b\" stroke-width=\"1.2\" stroke-dasharray=\"6 4\"><title>{}</title></line>",
            a.0, a.1, b.0, b.1, escape(name)
        );
    }
    if let Some((day, sigma, name)) = &c.date {
        let (l, r) = (f.at(day - sigma, y.1), f.at(day + sigma, y.0));
        let mid = (f.at(*day, y.0), f.at(*day, y.1));
        let _ = write!(
            o,
            "<g class=\"crossing\"><rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#b2182b\" fill-opacity=\"0.12\"/><line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#b2182b\" stroke-width=\"1.5\"/><title>{}</title></g>",
            l.0, l.1, (r.0 - l.0).max(1.0), r.1 - l.1, mid.0 .0, mid.0 .1, mid.1 .0, mid.1 .1,
            escape(name)
        );
        legend.push(("#b2182b", name.clone()));
    }
    if let Some(Line { from, to, name }) = &c.line {
        let (pa, pb) = (f.at(from.0, from.1), f.at(to.0, to.1));
        let _ = write!(
            o,
            "<line class=\"trend\" x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"{}\" stroke-width=\"2\"><title>{}</title></line>",
            pa.0, pa.1, pb.0, pb.1, color(1), escape(name)
        );
        legend.push((color(1), name.clone()));
    }
    points(&mut o, &f, &c.points);
    for (k, (fill, name)) in legend.iter().enumerate() {
        let ly = f.py.1 + 12.0 + 15.0 * k as f64;
        let _ = write!(
            o,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"10\" height=\"3\" fill=\"{fill}\"/><text x=\"{:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"11\">{}</text>",
            f.px.0 + 8.0,
            ly - 3.0,
            f.px.0 + 22.0,
            ly + 1.0,
            escape(name)
        );
    }
    with_overlay(svg, &o)
}

/// The points with their σ bars.
fn points(o: &mut String, f: &super::Frame, points: &[Dated]) {
    let _ = write!(
        o,
        "<g class=\"points\" fill=\"{}\" stroke=\"#222\" stroke-width=\"0.6\">",
        color(0)
    );
    for p in points
        .iter()
        .filter(|p| p.day.is_finite() && p.value.is_finite())
    {
        let (px, py) = f.at(p.day, p.value);
        if p.sigma > 0.0 && p.sigma.is_finite() {
            let (lo, hi) = (
                f.at(p.day, p.value - p.sigma).1,
                f.at(p.day, p.value + p.sigma).1,
            );
            let _ = write!(
                o,
                "<line x1=\"{px:.1}\" y1=\"{lo:.1}\" x2=\"{px:.1}\" y2=\"{hi:.1}\" stroke=\"#222\"/>"
            );
        }
        let _ = write!(
            o,
            "<circle class=\"point\" cx=\"{px:.1}\" cy=\"{py:.1}\" r=\"3.4\"><title>{}</title></circle>",
            escape(&p.hover)
        );
    }
    o.push_str("</g>");
}
