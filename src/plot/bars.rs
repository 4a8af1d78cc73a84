//! Horizontal bar chart: one band per category (names readable however long), one bar per
//! series in it; each bar carries `class="bar"` and a `<title>` with its value.

use super::axes::{plain, Axes, Frame};
use super::{color, escape, with_overlay};
use std::fmt::Write as _;

/// Options of [`bar_chart`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BarOptions {
    /// Logarithmic value axis (condition numbers, noise levels of different units); values
    /// ≤ 0 are drawn as empty bars.
    pub log: bool,
}

/// Bars of `series` (name, one value per category) over `categories`; a non-finite value is
/// an empty bar (the bar count stays categories × series).
pub fn bar_chart(
    title: &str,
    value_label: &str,
    categories: &[String],
    series: &[(String, Vec<f64>)],
    opts: &BarOptions,
) -> String {
    let band = (14.0 * series.len().max(1) as f64 + 10.0).max(22.0);
    let height = rpkm_core::convert::round_u32(96.0 + band * categories.len().max(1) as f64);
    let widest = categories
        .iter()
        .map(|c| c.chars().count())
        .max()
        .unwrap_or(4);
    let shown = |v: f64| {
        if opts.log {
            (v > 0.0 && v.is_finite()).then(|| v.log10())
        } else {
            v.is_finite().then_some(v)
        }
    };
    let values = series
        .iter()
        .flat_map(|s| s.1.iter().filter_map(|v| shown(*v)));
    let (lo, hi) = super::range(values.chain([if opts.log { f64::NAN } else { 0.0 }]), 0.05);
    let (lo, hi) = if opts.log {
        (lo.floor(), hi.ceil().max(lo.floor() + 1.0))
    } else {
        (lo.min(0.0), hi)
    };
    let axes = Axes {
        width: 720,
        height,
        caption: title,
        x_label: value_label,
        y_label: "",
        x: (lo, hi),
        y: (0.0, categories.len().max(1) as f64),
        y_label_area: (7 * u32::try_from(widest).unwrap_or(u32::MAX / 8) + 14).clamp(60, 260),
        x_ticks: Some(if opts.log { decade } else { plain }),
        y_ticks: None,
    };
    let (svg, f) = axes.draw();
    // bars grow from zero, or from the lowest decade of a log axis
    let base = if opts.log { lo } else { 0.0 };
    let mut o = String::from("<g class=\"bars\" font-family=\"sans-serif\" font-size=\"12\">");
    let bar_h = (band - 8.0) / series.len().max(1) as f64;
    for (c, name) in categories.iter().enumerate() {
        // first category on top
        let top = f.at(0.0, categories.len() as f64 - c as f64).1 + 4.0;
        let mid = top + (band - 8.0) / 2.0;
        let _ = write!(
            o,
            "<text x=\"{:.1}\" y=\"{mid:.1}\" dy=\"0.35em\" text-anchor=\"end\">{}</text>",
            f.px.0 - 6.0,
            escape(name)
        );
        for (s, (label, vals)) in series.iter().enumerate() {
            let v = vals.get(c).copied().unwrap_or(f64::NAN);
            let y = top + s as f64 * bar_h;
            let (x0, x1) = match shown(v) {
                Some(d) => (f.at(base.min(d), 0.0).0, f.at(base.max(d), 0.0).0),
                None => (f.px.0, f.px.0),
            };
            let _ = write!(
                o,
                "<rect class=\"bar\" x=\"{x0:.1}\" y=\"{y:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\"><title>{}: {}: {}</title></rect>",
                (x1 - x0).max(0.0),
                (bar_h - 1.0).max(1.0),
                color(s),
                escape(name),
                escape(label),
                value_text(v)
            );
        }
    }
    if series.len() > 1 {
        legend(&mut o, series, &f);
    }
    o.push_str("</g>");
    with_overlay(svg, &o)
}

/// The legend in a row at the top right, beside the caption.
fn legend(o: &mut String, series: &[(String, Vec<f64>)], f: &Frame) {
    for (s, (label, _)) in series.iter().enumerate() {
        let x = f.px.1 - 110.0 * (series.len() - s) as f64;
        let y = f.py.1 - 6.0;
        let _ = write!(
            o,
            "<rect x=\"{x:.1}\" y=\"{:.1}\" width=\"12\" height=\"10\" fill=\"{}\"/><text x=\"{:.1}\" y=\"{y:.1}\">{}</text>",
            y - 9.0,
            color(s),
            x + 16.0,
            escape(label)
        );
    }
}

/// A value for a tooltip: significant digits whatever its magnitude.
fn value_text(v: f64) -> String {
    if !v.is_finite() {
        "no value".to_owned()
    } else if v != 0.0 && !(1e-3..1e6).contains(&v.abs()) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

/// Tick label of a log10 axis: the decade.
#[expect(
    clippy::trivially_copy_pass_by_ref,
    reason = "a plotters label formatter: `&dyn Fn(&f64) -> String`"
)]
fn decade(v: &f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("1e{}", v.round())
    } else {
        String::new()
    }
}
