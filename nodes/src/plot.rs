//! Small SVG charts for the HTML reports, without dependencies.
//!
//! Every function returns a complete, standalone `<svg>` document (white background, title,
//! axes with ticks and labels, a legend where there are series) that a browser shows inline
//! in HTML. Output is deterministic: the same data give the same bytes. Text is XML-escaped.
//! Non-finite data (NaN, ±inf) are never written as coordinates: such points are skipped
//! (line, polar), drawn as empty bars (bar chart, so that the bar count stays
//! categories × series) or as grey cells (heat map). Empty data give an empty frame.
//!
//! Bars carry `class="bar"` and heat-map cells `class="cell"`, each with a `<title>` tooltip
//! giving the value, so that a browser shows it on hover.

mod chart;
mod field;
mod polar;
mod scale;
mod svg;

pub use chart::{bar_chart, line_chart};
pub use field::{heat_map, quiver};
pub use polar::polar_deviation;
pub use svg::escape;

/// Options of [`bar_chart`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BarOptions {
    /// Logarithmic y axis (for condition numbers); bars start at the bottom decade, values
    /// ≤ 0 are drawn as empty bars.
    pub log_y: bool,
}

/// Options of [`line_chart`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LineOptions {
    /// Join the points of a series with lines (broken where a point is not finite).
    pub lines: bool,
    /// Draw a marker on each point.
    pub markers: bool,
}

impl LineOptions {
    /// Lines without markers.
    pub const LINES: LineOptions = LineOptions {
        lines: true,
        markers: false,
    };
    /// Markers only: a scatter plot (residual against time or a covariate).
    pub const SCATTER: LineOptions = LineOptions {
        lines: false,
        markers: true,
    };
    /// Lines and markers.
    pub const LINES_AND_MARKERS: LineOptions = LineOptions {
        lines: true,
        markers: true,
    };
}

impl Default for LineOptions {
    fn default() -> Self {
        LineOptions::LINES
    }
}

/// Colours of the series (Tableau 10: distinct, readable on white).
const PALETTE: [&str; 10] = [
    "#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7",
    "#9c755f", "#bab0ac",
];

/// Colour of series `i`.
fn color(i: usize) -> &'static str {
    PALETTE.get(i % PALETTE.len()).copied().unwrap_or("#4e79a7")
}

#[cfg(test)]
mod tests;
