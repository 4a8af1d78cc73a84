//! Axis scales and ticks.

/// A data interval mapped onto a pixel interval, linear or logarithmic (base 10).
#[derive(Clone, Copy, Debug)]
pub struct Scale {
    /// Data interval (for a log scale: of log10 of the data).
    lo: f64,
    hi: f64,
    /// Pixel interval (`p0` at `lo`).
    p0: f64,
    p1: f64,
    log: bool,
}

impl Scale {
    /// A linear scale over the finite `values` (with `pad` fraction of margin on each side,
    /// but none below or above a 0 that `include_zero` brought in), onto pixels `p0..p1`.
    /// Empty or degenerate data give a unit interval.
    pub fn linear(
        values: impl IntoIterator<Item = f64>,
        include_zero: bool,
        pad: f64,
        p0: f64,
        p1: f64,
    ) -> Scale {
        let (mut lo, mut hi) = finite_range(values);
        if include_zero {
            lo = lo.min(0.0);
            hi = hi.max(0.0);
        }
        if !(lo.is_finite() && hi.is_finite()) {
            lo = 0.0;
            hi = 1.0;
        }
        if hi - lo <= f64::EPSILON * hi.abs().max(lo.abs()).max(1e-300) {
            let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
            lo -= d;
            hi += d;
        }
        let span = hi - lo;
        if !(include_zero && lo == 0.0) {
            lo -= pad * span;
        }
        if !(include_zero && hi == 0.0) {
            hi += pad * span;
        }
        Scale {
            lo,
            hi,
            p0,
            p1,
            log: false,
        }
    }

    /// A log10 scale over the finite positive `values`, onto pixels `p0..p1`, whole decades.
    pub fn log(values: impl IntoIterator<Item = f64>, p0: f64, p1: f64) -> Scale {
        let (lo, hi) = finite_range(values.into_iter().filter(|v| *v > 0.0).map(f64::log10));
        let (mut lo, mut hi) = if lo.is_finite() && hi.is_finite() {
            (lo.floor(), hi.ceil())
        } else {
            (0.0, 1.0)
        };
        if hi <= lo {
            hi = lo + 1.0;
        }
        if lo > hi - 1.0 {
            lo = hi - 1.0;
        }
        Scale {
            lo,
            hi,
            p0,
            p1,
            log: true,
        }
    }

    /// Whether the scale is logarithmic.
    pub fn is_log(&self) -> bool {
        self.log
    }

    /// Pixel of a data value; `None` where it cannot be shown (non-finite, or ≤ 0 on a log
    /// scale).
    pub fn px(&self, v: f64) -> Option<f64> {
        let u = if self.log {
            if v > 0.0 {
                v.log10()
            } else {
                return None;
            }
        } else {
            v
        };
        let p = self.p0 + (u - self.lo) / (self.hi - self.lo) * (self.p1 - self.p0);
        p.is_finite().then_some(p)
    }

    /// Pixel of a data value, clamped to the axis (for bar bases and out-of-range values).
    pub fn px_clamped(&self, v: f64) -> f64 {
        let (a, b) = (self.p0.min(self.p1), self.p0.max(self.p1));
        self.px(v).map_or(self.p0, |p| p.clamp(a, b))
    }

    /// The tick values and their labels (markup).
    pub fn ticks(&self) -> Vec<(f64, String)> {
        if self.log {
            let (lo, hi) = (self.lo as i32, self.hi as i32);
            let every = ((hi - lo) / 8 + 1).max(1);
            (lo..=hi)
                .filter(|k| (k - lo) % every == 0)
                .map(|k| (10f64.powi(k), decade_label(k)))
                .collect()
        } else {
            let step = nice_step(self.hi - self.lo, 6);
            if !(step.is_finite() && step > 0.0) {
                return Vec::new();
            }
            let first = (self.lo / step).ceil() as i64;
            let last = (self.hi / step + 1e-9).floor() as i64;
            if last < first || last - first > 50 {
                return Vec::new();
            }
            (first..=last)
                .map(|k| {
                    let v = k as f64 * step;
                    (v, label(v, step))
                })
                .collect()
        }
    }
}

/// Smallest and largest finite value; (+inf, -inf) when there is none.
pub fn finite_range(values: impl IntoIterator<Item = f64>) -> (f64, f64) {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        })
}

/// A step of 1, 2 or 5 × 10^k giving about `n` intervals over `span`.
pub fn nice_step(span: f64, n: usize) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    // Tolerance: 0.3 / 6 is 0.04999…, which must give 0.05.
    let nice = if f <= 1.0 + 1e-9 {
        1.0
    } else if f <= 2.0 + 1e-9 {
        2.0
    } else if f <= 5.0 + 1e-9 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

/// Label of tick `v` on an axis of tick spacing `step`.
pub fn label(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".to_owned();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) || step < 1e-4 {
        let s = format!("{v:.2e}");
        // 1.50e3 → 1.5e3
        match s.split_once('e') {
            Some((m, e)) => {
                let m = m.trim_end_matches('0').trim_end_matches('.');
                format!("{m}e{e}")
            }
            None => s,
        }
    } else {
        let decimals = (-step.log10().floor()).max(0.0) as usize;
        let s = format!("{v:.decimals$}");
        if s == "-0" {
            "0".to_owned()
        } else {
            s.replace('-', "\u{2212}")
        }
    }
}

/// `10^k` as markup with a superscript.
fn decade_label(k: i32) -> String {
    match k {
        0 => "1".to_owned(),
        1 => "10".to_owned(),
        _ => format!(
            r#"10<tspan dy="-5" font-size="9">{}</tspan>"#,
            k.to_string().replace('-', "\u{2212}")
        ),
    }
}
