//! The frame of every chart, drawn by plotters, and the mapping from data to its pixels.

use plotters::prelude::*;

/// What plotters draws: the canvas, caption, axes with their descriptions, the grid.
pub struct Axes<'a> {
    pub width: u32,
    pub height: u32,
    pub caption: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    /// Data ranges of the axes.
    pub x: (f64, f64),
    pub y: (f64, f64),
    /// Pixels left of the plotting area for the y tick labels (category names of a bar chart
    /// need more).
    pub y_label_area: u32,
    /// Tick labels of the axes; `None` draws no tick labels on that axis (categories drawn by
    /// the caller instead).
    pub x_ticks: Option<fn(&f64) -> String>,
    pub y_ticks: Option<fn(&f64) -> String>,
}

/// Tick label with as few digits as the ticks need.
#[expect(
    clippy::trivially_copy_pass_by_ref,
    reason = "a plotters label formatter: `&dyn Fn(&f64) -> String`"
)]
pub fn plain(v: &f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.0e}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

/// Where data coordinates land in the SVG: the plotting area's pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub x: (f64, f64),
    pub y: (f64, f64),
    /// Left and right pixel of the plotting area.
    pub px: (f64, f64),
    /// Bottom and top pixel (SVG y grows downwards: bottom > top).
    pub py: (f64, f64),
}

impl Frame {
    /// Pixel of data point (x, y).
    pub fn at(&self, x: f64, y: f64) -> (f64, f64) {
        (
            self.px.0 + (x - self.x.0) / (self.x.1 - self.x.0) * (self.px.1 - self.px.0),
            self.py.0 + (y - self.y.0) / (self.y.1 - self.y.0) * (self.py.1 - self.py.0),
        )
    }

    /// Pixels per data unit along x and along y (both positive).
    pub fn scale(&self) -> (f64, f64) {
        (
            (self.px.1 - self.px.0) / (self.x.1 - self.x.0),
            (self.py.0 - self.py.1) / (self.y.1 - self.y.0),
        )
    }
}

impl Axes<'_> {
    /// The SVG document of the frame and where its plotting area is. Drawing into a String
    /// cannot fail; a plotters error (none is known for the SVG backend) leaves a partial
    /// frame rather than no report.
    pub fn draw(&self) -> (String, Frame) {
        let mut svg = String::new();
        let mut frame = Frame {
            x: self.x,
            y: self.y,
            px: (0.0, f64::from(self.width)),
            py: (f64::from(self.height), 0.0),
        };
        {
            let root =
                SVGBackend::with_string(&mut svg, (self.width, self.height)).into_drawing_area();
            let _ = root.fill(&WHITE);
            let chart = ChartBuilder::on(&root)
                .caption(self.caption, ("sans-serif", 15))
                .margin(10)
                .x_label_area_size(38)
                .y_label_area_size(self.y_label_area)
                .build_cartesian_2d(self.x.0..self.x.1, self.y.0..self.y.1);
            if let Ok(mut chart) = chart {
                let mut mesh = chart.configure_mesh();
                mesh.x_desc(self.x_label)
                    .y_desc(self.y_label)
                    .axis_desc_style(("sans-serif", 13))
                    .label_style(("sans-serif", 11))
                    // the major grid only: a fine grid drowns maps and arrows
                    .light_line_style(TRANSPARENT)
                    .bold_line_style(RGBColor(225, 225, 225));
                match &self.x_ticks {
                    Some(f) => mesh.x_label_formatter(f).x_labels(8),
                    None => mesh.x_labels(0).disable_x_mesh(),
                };
                match &self.y_ticks {
                    Some(f) => mesh.y_label_formatter(f).y_labels(8),
                    None => mesh.y_labels(0).disable_y_mesh(),
                };
                let _ = mesh.draw();
                let (xs, ys) = chart.plotting_area().get_pixel_range();
                frame.px = (f64::from(xs.start), f64::from(xs.end));
                frame.py = (f64::from(ys.end), f64::from(ys.start));
            }
            let _ = root.present();
        }
        (svg, frame)
    }
}
