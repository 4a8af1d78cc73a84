//! Scatter plot: residual against time or a covariate; every marker has a `<title>` (file
//! line, pose, value, σ) so that a browser shows where it came from.

use super::axes::{plain, Axes};
use super::{color, escape, with_overlay};
use std::fmt::Write as _;

/// One marker: its position and the tooltip it carries.
#[derive(Clone, Debug)]
pub struct Marker {
    pub x: f64,
    pub y: f64,
    pub hover: String,
}

/// A named series of markers.
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub markers: Vec<Marker>,
}

/// Markers of every series (a colour each, a legend); a horizontal line at y = 0.
pub fn scatter(title: &str, x_label: &str, y_label: &str, series: &[Series]) -> String {
    let all = || series.iter().flat_map(|s| s.markers.iter());
    let x = super::range(all().map(|m| m.x), 0.03);
    let y = super::range(all().map(|m| m.y).chain([0.0]), 0.06);
    let axes = Axes {
        width: 540,
        height: 340,
        caption: title,
        x_label,
        y_label,
        x,
        y,
        y_label_area: 52,
        x_ticks: Some(plain),
        y_ticks: Some(plain),
    };
    let (svg, f) = axes.draw();
    let mut o = String::new();
    let (l, zero) = (f.at(x.0, 0.0), f.at(x.1, 0.0));
    let _ = write!(
        o,
        "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#555\" stroke-width=\"1\"/>",
        l.0, l.1, zero.0, zero.1
    );
    for (k, s) in series.iter().enumerate() {
        let _ = write!(
            o,
            "<g class=\"markers\" fill=\"{}\" fill-opacity=\"0.75\" stroke=\"#222\" stroke-width=\"0.4\">",
            color(k)
        );
        for m in s
            .markers
            .iter()
            .filter(|m| m.x.is_finite() && m.y.is_finite())
        {
            let (px, py) = f.at(m.x, m.y);
            let _ = write!(
                o,
                "<circle class=\"point\" cx=\"{px:.1}\" cy=\"{py:.1}\" r=\"3.2\"><title>{}</title></circle>",
                escape(&m.hover)
            );
        }
        o.push_str("</g>");
        // legend above the plotting area, right-aligned: it hides no point
        let lx = f.px.1 - 80.0 * (series.len() - k) as f64;
        let _ = write!(
            o,
            "<circle cx=\"{lx:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{}\"/><text x=\"{:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"12\">{}</text>",
            f.py.1 - 10.0,
            color(k),
            lx + 8.0,
            f.py.1 - 6.0,
            escape(&s.name)
        );
    }
    with_overlay(svg, &o)
}
