//! How a parameter moves over a machine's calibrations: a straight line fitted by weighted
//! least squares to its values (each weighted by its own σ) over the longest recent run of
//! calibrations that a line explains, its slope's significance, and when the line leaves the
//! parameter's tolerance band, with that date's σ.
//!
//! The run: a crash or a repair breaks a parameter's history into pieces that no one line
//! fits. Starting from every calibration, the oldest is dropped while the line's χ² is beyond
//! what noise gives once in 1/[`LINE_P_VALUE`] times, so the trend is that of the machine as
//! it has been since its last break. Where the scatter exceeds the stated σ (χ²/dof > 1) the
//! line's σ are widened by √(χ²/dof), as the stated σ then understate it.

use crate::stats::chi2_upper_tail;

/// A line explains a run when its χ² is at least this likely under noise alone.
pub const LINE_P_VALUE: f64 = 1e-3;

/// Calibrations a trend needs: a line and one degree of freedom to test it.
pub const MIN_POINTS: usize = 3;

/// One calibration's value of a parameter.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TrendPoint {
    /// s, any origin.
    pub t_s: f64,
    /// mm, rad.
    pub value: f64,
    pub sigma: f64,
}

/// A parameter's line over the run of calibrations it fits.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Trend {
    /// The first point of the run (an index into the points given) and how many follow.
    pub from: usize,
    pub points: usize,
    /// The weighted mean time of the run, s: where value and slope are uncorrelated.
    pub t_mean_s: f64,
    /// The line's value at `t_mean_s` and its σ.
    pub value: f64,
    pub sigma_value: f64,
    /// Slope (unit per s) and its σ.
    pub slope: f64,
    pub sigma_slope: f64,
    /// χ² of the points about the line and its degrees of freedom.
    pub chi2: f64,
    pub dof: usize,
}

impl Trend {
    /// The slope in σ.
    pub fn z(&self) -> f64 {
        self.slope / self.sigma_slope
    }

    /// The line at time `t_s`.
    pub fn at(&self, t_s: f64) -> f64 {
        self.value + self.slope * (t_s - self.t_mean_s)
    }
}

/// When a trend's line leaves a tolerance band.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Crossing {
    /// The bound it crosses (nominal ± tolerance; mm, rad).
    pub bound: f64,
    /// When, s (the points' origin), and its σ.
    pub t_s: f64,
    pub sigma_s: f64,
}

/// The weighted line through `points`, σ widened by √(χ²/dof) where that exceeds 1; None
/// for fewer than [`MIN_POINTS`], a σ that is not positive, or a run of one instant.
fn fit(points: &[TrendPoint]) -> Option<Trend> {
    if points.len() < MIN_POINTS
        || points
            .iter()
            .any(|p| !(p.sigma > 0.0 && p.sigma.is_finite() && p.value.is_finite()))
    {
        return None;
    }
    let w = |p: &TrendPoint| 1.0 / (p.sigma * p.sigma);
    let sw: f64 = points.iter().map(w).sum();
    let t_mean = points.iter().map(|p| w(p) * p.t_s).sum::<f64>() / sw;
    let value = points.iter().map(|p| w(p) * p.value).sum::<f64>() / sw;
    let stt: f64 = points.iter().map(|p| w(p) * (p.t_s - t_mean).powi(2)).sum();
    if !(stt > 0.0) {
        return None;
    }
    let slope = points
        .iter()
        .map(|p| w(p) * (p.t_s - t_mean) * (p.value - value))
        .sum::<f64>()
        / stt;
    let chi2: f64 = points
        .iter()
        .map(|p| w(p) * (p.value - value - slope * (p.t_s - t_mean)).powi(2))
        .sum();
    let dof = points.len() - 2;
    let widen = (chi2 / dof as f64).max(1.0).sqrt();
    Some(Trend {
        from: 0,
        points: points.len(),
        t_mean_s: t_mean,
        value,
        sigma_value: widen / sw.sqrt(),
        slope,
        sigma_slope: widen / stt.sqrt(),
        chi2,
        dof,
    })
}

/// The trend of `points` (in time order) over the longest recent run a line explains; None
/// when fewer than [`MIN_POINTS`] recent points lie on a line.
pub fn trend(points: &[TrendPoint]) -> Option<Trend> {
    (0..points.len().saturating_sub(MIN_POINTS - 1)).find_map(|from| {
        let t = fit(&points[from..])?;
        (chi2_upper_tail(t.chi2, t.dof as f64) >= LINE_P_VALUE).then_some(Trend { from, ..t })
    })
}

/// When the trend's line leaves `nominal ± tolerance` on the side it moves to: the time its
/// line reaches that bound, with the σ of the value and the slope propagated (uncorrelated at
/// the run's mean time): σ_t² = (σ_v² + (t − t̄)² σ_b²) / b². None for a flat line.
pub fn crossing(trend: &Trend, nominal: f64, tolerance: f64) -> Option<Crossing> {
    let b = trend.slope;
    if !(b != 0.0 && b.is_finite()) {
        return None;
    }
    let bound = nominal + tolerance.copysign(b);
    let dt = (bound - trend.value) / b;
    let sigma = ((trend.sigma_value.powi(2) + (dt * trend.sigma_slope).powi(2)) / (b * b)).sqrt();
    Some(Crossing {
        bound,
        t_s: trend.t_mean_s + dt,
        sigma_s: sigma,
    })
}
