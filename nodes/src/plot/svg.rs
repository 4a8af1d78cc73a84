//! A minimal SVG writer: escaping, number formatting, a few primitives.

use std::fmt::Write as _;

/// Escapes text for XML content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // Characters XML 1.0 forbids (control characters but tab and line breaks).
            c if (c as u32) < 0x20 && !matches!(c, '\t' | '\n' | '\r') => out.push('\u{FFFD}'),
            '\u{FFFE}' | '\u{FFFF}' => out.push('\u{FFFD}'),
            c => out.push(c),
        }
    }
    out
}

/// A coordinate: two decimals, trailing zeros removed; non-finite values (which the callers
/// never pass on purpose) become 0 so that the document stays valid.
pub fn num(v: f64) -> String {
    if !v.is_finite() {
        return "0".to_owned();
    }
    let s = format!("{v:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" || s.is_empty() {
        "0".to_owned()
    } else {
        s.to_owned()
    }
}

/// Text anchor of [`Svg::text`].
#[derive(Clone, Copy)]
pub enum Anchor {
    Start,
    Middle,
    End,
}

impl Anchor {
    fn as_str(self) -> &'static str {
        match self {
            Anchor::Start => "start",
            Anchor::Middle => "middle",
            Anchor::End => "end",
        }
    }
}

/// An SVG document being written.
pub struct Svg {
    out: String,
}

/// Font of every chart.
pub const FONT: &str = "DejaVu Sans, Helvetica, Arial, sans-serif";

impl Svg {
    /// A document of `width` × `height` px with a white background.
    pub fn new(width: f64, height: f64) -> Svg {
        let mut out = String::new();
        let _ = write!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="{FONT}" font-size="12">"#,
            w = num(width),
            h = num(height)
        );
        out.push('\n');
        let _ = writeln!(
            out,
            r##"<rect x="0" y="0" width="{}" height="{}" fill="#ffffff"/>"##,
            num(width),
            num(height)
        );
        Svg { out }
    }

    /// Appends raw markup (already escaped).
    pub fn raw(&mut self, markup: &str) {
        self.out.push_str(markup);
        self.out.push('\n');
    }

    /// A rectangle; `extra` holds further attributes (escaped by the caller).
    pub fn rect(&mut self, x: f64, y: f64, w: f64, h: f64, fill: &str, extra: &str) {
        let _ = writeln!(
            self.out,
            r#"<rect x="{}" y="{}" width="{}" height="{}" fill="{}"{}{}/>"#,
            num(x),
            num(y),
            num(w.max(0.0)),
            num(h.max(0.0)),
            fill,
            if extra.is_empty() { "" } else { " " },
            extra
        );
    }

    /// A line segment.
    pub fn line(&mut self, x1: f64, y1: f64, x2: f64, y2: f64, stroke: &str, width: f64) {
        self.line_with(x1, y1, x2, y2, stroke, width, "");
    }

    /// A line segment with further attributes.
    #[allow(clippy::too_many_arguments)] // Coordinates and style of one element.
    pub fn line_with(
        &mut self,
        x1: f64,
        y1: f64,
        x2: f64,
        y2: f64,
        stroke: &str,
        width: f64,
        extra: &str,
    ) {
        let _ = writeln!(
            self.out,
            r#"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="{}" stroke-width="{}"{}{}/>"#,
            num(x1),
            num(y1),
            num(x2),
            num(y2),
            stroke,
            num(width),
            if extra.is_empty() { "" } else { " " },
            extra
        );
    }

    /// A circle.
    pub fn circle(&mut self, cx: f64, cy: f64, r: f64, fill: &str, extra: &str) {
        let _ = writeln!(
            self.out,
            r#"<circle cx="{}" cy="{}" r="{}" fill="{}"{}{}/>"#,
            num(cx),
            num(cy),
            num(r),
            fill,
            if extra.is_empty() { "" } else { " " },
            extra
        );
    }

    /// An open polyline through `points` (px); nothing for fewer than two points.
    pub fn polyline(&mut self, points: &[(f64, f64)], stroke: &str, width: f64, extra: &str) {
        if points.len() < 2 {
            return;
        }
        let pts: Vec<String> = points
            .iter()
            .map(|&(x, y)| format!("{},{}", num(x), num(y)))
            .collect();
        let _ = writeln!(
            self.out,
            r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="{}" stroke-linejoin="round"{}{}/>"#,
            pts.join(" "),
            stroke,
            num(width),
            if extra.is_empty() { "" } else { " " },
            extra
        );
    }

    /// A closed polygon through `points` (px).
    pub fn polygon(&mut self, points: &[(f64, f64)], fill: &str, extra: &str) {
        let pts: Vec<String> = points
            .iter()
            .map(|&(x, y)| format!("{},{}", num(x), num(y)))
            .collect();
        let _ = writeln!(
            self.out,
            r#"<polygon points="{}" fill="{}"{}{}/>"#,
            pts.join(" "),
            fill,
            if extra.is_empty() { "" } else { " " },
            extra
        );
    }

    /// Text (escaped here) at (x, y), rotated by `rotate` degrees about that point.
    pub fn text(&mut self, x: f64, y: f64, size: f64, anchor: Anchor, text: &str, rotate: f64) {
        self.text_markup(x, y, size, anchor, &escape(text), rotate, "");
    }

    /// Text whose content is markup (already escaped, may hold `tspan`s).
    #[allow(clippy::too_many_arguments)] // Position and style of one element.
    pub fn text_markup(
        &mut self,
        x: f64,
        y: f64,
        size: f64,
        anchor: Anchor,
        markup: &str,
        rotate: f64,
        extra: &str,
    ) {
        let transform = if rotate != 0.0 {
            format!(
                r#" transform="rotate({} {} {})""#,
                num(rotate),
                num(x),
                num(y)
            )
        } else {
            String::new()
        };
        let _ = writeln!(
            self.out,
            r##"<text x="{}" y="{}" font-size="{}" text-anchor="{}" fill="#222222"{}{}{}>{}</text>"##,
            num(x),
            num(y),
            num(size),
            anchor.as_str(),
            transform,
            if extra.is_empty() { "" } else { " " },
            extra,
            markup
        );
    }

    /// Closes the document.
    pub fn finish(mut self) -> String {
        self.out.push_str("</svg>\n");
        self.out
    }
}
