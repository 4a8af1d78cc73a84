//! Circular test plot: a ball-bar circle with exaggerated radial deviation.

use super::chart::{title, TICK_SIZE};
use super::scale::{label, nice_step};
use super::svg::{escape, Anchor, Svg};

/// Circular test (ball-bar) plot: the measured radial deviation `deviation_um[i]` (µm, positive
/// outward) at angle `angles_rad[i]` (rad, counter-clockwise from +x), drawn around the
/// nominal circle of radius `nominal_radius_mm` with the deviation exaggerated so that the
/// largest one is a quarter of the radius on screen. Dotted rings mark ± a round deviation;
/// the subtitle gives the exaggeration factor, the mean deviation (radius deviation) and
/// max − min (circularity). Pairs with a non-finite member are skipped; extra entries of the
/// longer slice are ignored.
pub fn polar_deviation(
    title_text: &str,
    angles_rad: &[f64],
    deviation_um: &[f64],
    nominal_radius_mm: f64,
) -> String {
    let width = 600.0;
    let height = 660.0;
    let (cx, cy) = (width / 2.0, 345.0);
    let r_px = 180.0;
    let data: Vec<(f64, f64)> = angles_rad
        .iter()
        .zip(deviation_um)
        .map(|(&a, &d)| (a, d))
        .filter(|(a, d)| a.is_finite() && d.is_finite())
        .collect();
    let peak = data.iter().map(|p| p.1.abs()).fold(0.0f64, f64::max);
    let ring = if peak > 0.0 {
        let s = nice_step(peak, 2);
        if s > peak {
            s / 2.0
        } else {
            s
        }
    } else {
        1.0
    };
    let scale_um = if peak > 0.0 { peak } else { ring };
    let gain = r_px * 0.25 / scale_um; // px per µm
    let true_gain = if nominal_radius_mm.is_finite() && nominal_radius_mm > 0.0 {
        r_px / (nominal_radius_mm * 1000.0)
    } else {
        f64::NAN
    };
    let factor = gain / true_gain;

    let mut svg = Svg::new(width, height);
    title(&mut svg, width, title_text);
    let subtitle = {
        let n = data.len();
        let mut s = if factor.is_finite() {
            format!(
                "nominal radius {} mm, deviation ×{}",
                label(nominal_radius_mm, 1.0),
                label(factor.round(), 1.0)
            )
        } else {
            "deviation exaggerated".to_owned()
        };
        if n > 0 {
            let mean = data.iter().map(|p| p.1).sum::<f64>() / n as f64;
            let (lo, hi) = data
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                    (a.min(p.1), b.max(p.1))
                });
            s.push_str(&format!(
                "; mean deviation {:.1} µm, circularity {:.1} µm",
                mean,
                hi - lo
            ));
        }
        s
    };
    svg.text(
        width / 2.0,
        52.0,
        TICK_SIZE + 1.0,
        Anchor::Middle,
        &subtitle,
        0.0,
    );

    // Spokes and angle labels.
    for k in 0..8 {
        let a = k as f64 * std::f64::consts::FRAC_PI_4;
        let (c, s) = (a.cos(), a.sin());
        let outer = r_px * 1.25 + 16.0;
        svg.line(cx, cy, cx + c * outer, cy - s * outer, "#e6e6e6", 1.0);
        svg.text(
            cx + c * (outer + 14.0),
            cy - s * (outer + 14.0) + 4.0,
            TICK_SIZE,
            Anchor::Middle,
            &format!("{}°", k * 45),
            0.0,
        );
    }
    // Nominal circle and ± rings.
    svg.circle(
        cx,
        cy,
        r_px,
        "none",
        r##"stroke="#888888" stroke-width="1.2" stroke-dasharray="6 4""##,
    );
    for sign in [-1.0, 1.0] {
        let rr = r_px + sign * ring * gain;
        svg.circle(
            cx,
            cy,
            rr,
            "none",
            r##"stroke="#bbbbbb" stroke-width="1" stroke-dasharray="2 3""##,
        );
        let text = format!(
            "{}{} µm",
            if sign > 0.0 { "+" } else { "\u{2212}" },
            label(ring, ring)
        );
        let a = 0.35f64; // label position, rad
        svg.text_markup(
            cx + rr * a.cos() + 4.0,
            cy - rr * a.sin(),
            TICK_SIZE - 1.0,
            Anchor::Start,
            &escape(&text),
            0.0,
            r##"stroke="#ffffff" stroke-width="3" paint-order="stroke""##,
        );
    }
    // The measured profile (closed).
    let pts: Vec<(f64, f64)> = data
        .iter()
        .map(|&(a, d)| {
            let rr = (r_px + d * gain).max(0.0);
            (cx + rr * a.cos(), cy - rr * a.sin())
        })
        .collect();
    if pts.len() >= 2 {
        let mut closed = pts.clone();
        if let Some(&first) = pts.first() {
            closed.push(first);
        }
        svg.polyline(&closed, "#c0392b", 2.0, "");
    }
    for &(x, y) in &pts {
        svg.circle(x, y, 2.2, "#c0392b", "");
    }
    svg.circle(cx, cy, 2.5, "#444444", "");
    // Legend.
    let ly = height - 22.0;
    svg.line(40.0, ly, 64.0, ly, "#888888", 1.2);
    svg.text(
        70.0,
        ly + 4.0,
        TICK_SIZE,
        Anchor::Start,
        "nominal circle",
        0.0,
    );
    svg.line(200.0, ly, 224.0, ly, "#c0392b", 2.0);
    svg.text(
        230.0,
        ly + 4.0,
        TICK_SIZE,
        Anchor::Start,
        "measured (radial deviation exaggerated)",
        0.0,
    );
    svg.finish()
}
