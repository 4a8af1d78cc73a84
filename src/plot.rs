//! The charts of the reports, as inline SVG.
//!
//! plotters (its SVG backend) draws what a plotting library draws: frames, axes, ticks,
//! grids, captions. What is ours is drawn over its plotting area through [`Frame`]: the
//! machine from rpkm-core's geometry ([`machine`]), residual maps whose colour scale two panels
//! share ([`maps`]), error-vector maps, bars and markers that carry a `<title>` (file line,
//! pose, value, σ) which a browser shows on hover; quantities over calendar time with their
//! σ, a fitted line and a tolerance band ([`time_chart`]: a machine's history).
//!
//! Output is deterministic (the same data give the same bytes) and text is XML-escaped.
//! Non-finite values are never written as coordinates: such points are left off.

mod axes;
mod bars;
pub mod machine;
pub mod maps;
mod scatter;
mod series;

pub use axes::{Axes, Frame};
pub use bars::{bar_chart, BarOptions};
pub use scatter::{scatter, Marker, Series};
pub use series::{time_chart, Dated, Line, TimeChart};

/// Colours of the series (Tableau 10: distinct, readable on white and in print).
const PALETTE: [&str; 10] = [
    "#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7",
    "#9c755f", "#bab0ac",
];

/// Colour of series `i`.
pub fn color(i: usize) -> &'static str {
    PALETTE.get(i % PALETTE.len()).copied().unwrap_or("#4e79a7")
}

/// Text made safe for XML/HTML content and attribute values; control characters other than
/// tab and newline (invalid in XML 1.0) are dropped.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            '\t' | '\n' => out.push(c),
            c if c.is_control() => {}
            c => out.push(c),
        }
    }
    out
}

/// `svg` (a complete document) with `overlay` inserted just before its closing tag.
fn with_overlay(mut svg: String, overlay: &str) -> String {
    match svg.rfind("</svg>") {
        Some(end) => svg.insert_str(end, overlay),
        None => svg.push_str(overlay),
    }
    svg
}

/// Lower and upper end of the finite values, widened by `pad` of the span on each side (a
/// single value or none gives a unit span around it).
pub fn range(values: impl IntoIterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.into_iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= f64::EPSILON * hi.abs().max(1.0) {
        return (lo - 0.5, hi + 0.5);
    }
    (lo - pad * span, hi + pad * span)
}

#[cfg(test)]
mod tests;
