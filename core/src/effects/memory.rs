//! Covariates with memory: what a row alone does not hold. A thermometer that lags the part
//! it stands for reads the part's temperature of some minutes ago; the part's temperature is
//! the reading plus its lag times the reading's rate. Both are evaluated along the campaign's
//! time (`t`), each campaign over its own rows: a held-out campaign is never continued from the
//! calibration's.
//!
//! - [`rate`]: dT/dt at every row, the slope of a quadratic fitted over a window in time
//!   around the row. The window's width is the one whose error is least: the thermometer's
//!   noise (estimated from the readings themselves) through the fit, and the bend the fit
//!   misses, each width's measured against the next narrower one's.
//! - [`carried_temperature`], [`carried_rate`]: the reading's least-squares fit in smooth
//!   terms over the campaign ([`smooth_terms`] at [`rate`]'s window) and its derivative, with
//!   the modes of their error (its covariance exact: the readings' noise through the fit), for
//!   a fit that carries that error (`thermal`, `thermal_lag`).
//! - [`Lagged`]: `lag(T, τ)`, the temperature of a part whose thermometer `T` follows it with a
//!   first-order lag of time constant τ (seconds). τ > 0: the thermometer lags the part, whose
//!   temperature is `T + τ · dT/dt` (the first-order lag undone). τ < 0: the part lags the
//!   thermometer by |τ|, `T` filtered in time order by `|τ| · dy/dt = T − y`, between rows
//!   linear in time (exact for a reading that is), the part in equilibrium with the first row's
//!   reading before it. τ = 0: the reading. The derivative by τ is exact in both branches and
//!   `dT/dt` at τ = 0 from either side.

use std::sync::{Arc, Mutex};

/// Most smooth terms in time of a thermometer's error ([`smooth_terms`]): a wander of a
/// fifteenth of the campaign (an hour's campaign whose rate is fitted over four minutes).
pub const MOST_SMOOTH_TERMS: usize = 30;

/// Legendre polynomials in the campaign's time `t` (each at every row), two per half-width
/// `half` of a rate's window plus one, at least 2 and at most [`MOST_SMOOTH_TERMS`]: the
/// smooth error a rate fitted over that window leaves, which wanders on the scale of the
/// half-width (a basis follows a wander with two terms to it, as a signal is sampled at
/// twice its highest frequency). None where the times span nothing.
pub fn smooth_terms(t: &[f64], half: f64) -> Option<Vec<Vec<f64>>> {
    let (lo, hi) = t
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let span = hi - lo;
    if !(span > 0.0 && half > 0.0) {
        return None;
    }
    let n = (2..MOST_SMOOTH_TERMS)
        .find(|&n| f64::from(u32::try_from(n - 1).unwrap_or(u32::MAX)) >= 2.0 * span / half)
        .unwrap_or(MOST_SMOOTH_TERMS);
    let u: Vec<f64> = t.iter().map(|v| 2.0 * (v - lo) / span - 1.0).collect();
    Some(
        (0..n)
            .map(|k| u.iter().map(|&u| legendre(k, u)).collect())
            .collect(),
    )
}

/// The Legendre polynomial of degree `k` at `u` (Bonnet's recursion).
fn legendre(k: usize, u: f64) -> f64 {
    let (mut a, mut b) = (1.0, u);
    if k == 0 {
        return a;
    }
    for n in 1..k {
        let n = n as f64;
        (a, b) = (b, ((2.0 * n + 1.0) * u * b - n * a) / (n + 1.0));
    }
    b
}

/// Why a rate or lag cannot be made of a column.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MemoryError {
    #[error("needs at least 3 rows at distinct times `t`, found {0}")]
    TooFewTimes(usize),
    #[error("`t` is not finite at row {0}")]
    BadTime(usize),
}

/// The rows of one campaign in time order (stable among equal times).
#[derive(Clone, Debug)]
pub struct Timeline {
    order: Vec<usize>,
    t: Vec<f64>,
}

impl Timeline {
    /// The rows with times `t` (in row order) sorted by time.
    pub fn new(t: &[f64]) -> Result<Timeline, MemoryError> {
        if let Some(i) = t.iter().position(|v| !v.is_finite()) {
            return Err(MemoryError::BadTime(i));
        }
        let mut order: Vec<usize> = (0..t.len()).collect();
        order.sort_by(|&a, &b| t[a].total_cmp(&t[b]));
        let sorted: Vec<f64> = order.iter().map(|&i| t[i]).collect();
        let distinct = 1 + sorted.windows(2).filter(|w| w[1] > w[0]).count();
        if t.is_empty() || distinct < 3 {
            return Err(MemoryError::TooFewTimes(if t.is_empty() {
                0
            } else {
                distinct
            }));
        }
        Ok(Timeline { order, t: sorted })
    }

    /// `x` (row order) in time order.
    fn sorted(&self, x: &[f64]) -> Vec<f64> {
        self.order.iter().map(|&i| x[i]).collect()
    }

    /// `v` (time order) back in row order.
    fn unsorted<T: Copy + Default>(&self, v: &[T]) -> Vec<T> {
        let mut out = vec![T::default(); v.len()];
        for (k, &i) in self.order.iter().enumerate() {
            out[i] = v[k];
        }
        out
    }
}

/// dx/dt at every row (row order) of `x` read at `line`'s times: see the module
/// documentation. The window's half-width doubles from three rows' steps to half the
/// campaign; each width's error is its noise (the readings' noise through the fit) and its
/// bias (a window twice as wide bends four times as much: the change from the narrower
/// width is three quarters of the wider one's bias), and the width with the least of both
/// is kept. A lag of τ turns the rate's error into τ times as much temperature. (A local
/// cubic, whose bias grows with the width's fourth power, erred less on the twin's swing,
/// but moved the independent simulator's time constant from 886 ± 5 s to 845 ± 4 s against
/// its 900: the quadratic stays.)
pub fn rate(line: &Timeline, x: &[f64]) -> Vec<f64> {
    rate_fit(line, x).0
}

/// The half-width (s) of the window [`rate`] fits `x` over.
pub fn rate_window(line: &Timeline, x: &[f64]) -> f64 {
    rate_fit(line, x).1
}

/// [`rate`] and the half-width (s) of its window.
fn rate_fit(line: &Timeline, x: &[f64]) -> (Vec<f64>, f64) {
    let xs = line.sorted(x);
    let noise = reading_noise(&line.t, &xs);
    let best = least_error_rate(&line.t, &xs, noise);
    (line.unsorted(&best.rate), best.half)
}

/// A rate (time order) of a local quadratic, its window's half-width and its estimated
/// error (a variance, (K/s)²).
struct Fitted {
    rate: Vec<f64>,
    half: f64,
    error: f64,
}

/// The rate of a local quadratic over the width of least estimated error.
fn least_error_rate(t: &[f64], xs: &[f64], noise: f64) -> Fitted {
    let span = t[t.len() - 1] - t[0];
    let narrowest = 3.0 * median_step(t);
    let widest = (span / 2.0).max(narrowest);
    let unbias = (4.0 / 3.0_f64).powi(2);
    let mut half = narrowest;
    let (first, spread) = slopes(t, xs, half);
    let (mut previous, mut previous_noise) = (first.clone(), noise * spread);
    let mut best = Fitted {
        rate: first,
        half,
        error: (noise * spread).powi(2),
    };
    while half < widest {
        half = (2.0 * half).min(widest);
        let (slope, spread) = slopes(t, xs, half);
        let change: Vec<f64> = slope.iter().zip(&previous).map(|(a, b)| a - b).collect();
        let bias2 = (rms(&change).powi(2) - previous_noise.powi(2)).max(0.0) * unbias;
        let error = (noise * spread).powi(2) + bias2;
        if error < best.error {
            best = Fitted {
                rate: slope.clone(),
                half,
                error,
            };
        }
        (previous, previous_noise) = (slope, noise * spread);
    }
    best
}

/// The slope at each time of a quadratic fitted to the readings within `half` of it (at
/// least the three nearest distinct times), and the RMS over the rows of each slope's
/// standard deviation per unit of the readings' noise.
fn slopes(t: &[f64], x: &[f64], half: f64) -> (Vec<f64>, f64) {
    let n = t.len();
    let (mut lo, mut hi) = (0usize, 0usize);
    let mut spread = 0.0;
    let slope = (0..n)
        .map(|i| {
            while t[lo] < t[i] - half {
                lo += 1;
            }
            while hi + 1 < n && t[hi + 1] <= t[i] + half {
                hi += 1;
            }
            let (a, b) = widened(t, i, (lo, hi));
            let (s, var) = quadratic_slope(&t[a..=b], &x[a..=b], t[i]);
            spread += var;
            s
        })
        .collect();
    (slope, (spread / n.max(1) as f64).sqrt())
}

/// The window `lo..=hi` around row `i` grown until it holds three distinct times (or every
/// row).
fn widened(t: &[f64], i: usize, (mut lo, mut hi): (usize, usize)) -> (usize, usize) {
    let distinct = |lo: usize, hi: usize| 1 + t[lo..=hi].windows(2).filter(|w| w[1] > w[0]).count();
    while distinct(lo, hi) < 3 {
        let left = (lo > 0).then(|| t[i] - t[lo - 1]);
        let right = (hi + 1 < t.len()).then(|| t[hi + 1] - t[i]);
        match (left, right) {
            (Some(l), Some(r)) if l <= r => lo -= 1,
            (_, Some(_)) => hi += 1,
            (Some(_), None) => lo -= 1,
            (None, None) => break,
        }
    }
    (lo, hi)
}

/// The slope at `at` of the least-squares quadratic through (t, x) (a line where the
/// window's distinct times do not determine it), and its variance per unit variance of the
/// readings.
fn quadratic_slope(t: &[f64], x: &[f64], at: f64) -> (f64, f64) {
    let scale = t
        .iter()
        .map(|v| (v - at).abs())
        .fold(0.0_f64, f64::max)
        .max(f64::MIN_POSITIVE);
    // the normal equations from the sums of u^k and x·u^k, u the scaled time
    let (mut su, mut sx) = ([0.0_f64; 5], [0.0_f64; 3]);
    for (tk, xk) in t.iter().zip(x) {
        let u = (tk - at) / scale;
        let mut p = 1.0;
        for (k, s) in su.iter_mut().enumerate() {
            *s += p;
            if k < sx.len() {
                sx[k] += xk * p;
            }
            p *= u;
        }
    }
    let distinct = 1 + t.windows(2).filter(|w| w[1] > w[0]).count();
    let mut d = distinct.saturating_sub(1).min(2);
    while d >= 1 {
        let normal = nalgebra::DMatrix::from_fn(d + 1, d + 1, |r, c| su[r + c]);
        if let Some(inv) = normal.try_inverse() {
            let coef = &inv * nalgebra::DVector::from_column_slice(&sx[..=d]);
            return (coef[1] / scale, inv[(1, 1)] / (scale * scale));
        }
        d -= 1;
    }
    (0.0, 0.0)
}

/// A thermometer's temperature or rate for a fit that carries its smooth error
/// ([`carried_temperature`], [`carried_rate`]), row order.
pub struct CarriedReading {
    /// The temperature (or rate) at every row.
    pub value: Vec<f64>,
    /// The modes of its smooth error.
    pub errors: Modes,
}

/// The modes of a reading's smooth error a fit carries: each at every row (row order), and
/// its standard deviation (K, or K/s for a rate), largest first.
#[derive(Clone, Debug, Default)]
pub struct Modes {
    pub modes: Vec<Vec<f64>>,
    pub sigma: Vec<f64>,
}

/// The smooth terms of a column (time order) at its rate's window, their projection, and
/// what chose them.
struct Smooth {
    noise: f64,
    /// rows × terms: each term at every row (time order).
    v: nalgebra::DMatrix<f64>,
    /// The reading's least-squares coefficients in the terms, and their covariance
    /// σ² (VᵀV)⁻¹.
    coef: nalgebra::DVector<f64>,
    covariance: nalgebra::DMatrix<f64>,
}

impl Smooth {
    /// The fit of `x` in the smooth terms at its rate's window, where it stands for the
    /// reading: it holds the readings to their noise ([`HELD_TO_NOISE`]: a temperature set
    /// in steps it does not) and the reading moves beyond its noise ([`MOVES_LEVEL`]: a
    /// temperature that does not holds no expansion to carry, and its modes would let
    /// α · mode stand for anything; on the series' machines held at 20 °C, α ran to
    /// −20000 ± 80000 ppm/K). None where it does not, the times span nothing or the readings
    /// show no noise.
    fn of(line: &Timeline, x: &[f64]) -> Option<Smooth> {
        let xs = line.sorted(x);
        let noise = reading_noise(&line.t, &xs);
        let half = least_error_rate(&line.t, &xs, noise).half;
        let basis = smooth_terms(&line.t, half).filter(|_| noise > 0.0)?;
        let v = nalgebra::DMatrix::from_fn(line.t.len(), basis.len(), |i, k| basis[k][i]);
        let inverse = (v.transpose() * &v).try_inverse()?;
        let readings = nalgebra::DVector::from_column_slice(&xs);
        let coef = &inverse * (v.transpose() * &readings);
        let smooth = Smooth {
            noise,
            covariance: inverse * noise.powi(2),
            coef,
            v,
        };
        (smooth.holds(&readings) && smooth.moves()).then_some(smooth)
    }

    /// Whether the terms hold the readings to their noise: the residual's mean square
    /// against the noise's, with its dof.
    fn holds(&self, readings: &nalgebra::DVector<f64>) -> bool {
        let (rows, n) = self.v.shape();
        let off = (&self.v * &self.coef - readings).norm_squared();
        off / (rows.saturating_sub(n).max(1) as f64) <= HELD_TO_NOISE * self.noise.powi(2)
    }

    /// Whether the reading moves beyond its noise: the fit's terms but the constant, against
    /// their covariance, at [`MOVES_LEVEL`].
    fn moves(&self) -> bool {
        let n = self.v.ncols();
        if n < 2 {
            return false;
        }
        let a = self.coef.rows(1, n - 1).into_owned();
        let Some(inverse) = self
            .covariance
            .view((1, 1), (n - 1, n - 1))
            .into_owned()
            .try_inverse()
        else {
            return false;
        };
        let chi2 = (a.transpose() * inverse * &a)[(0, 0)];
        crate::stats::chi2_upper_tail(chi2, (n - 1) as f64) < MOVES_LEVEL
    }

    /// The coefficients of a series' derivative in time from its own (terms × terms):
    /// P_k' = Σ (2j + 1) P_j over j < k with k − j odd, times du/dt.
    fn derivative(&self, line: &Timeline) -> nalgebra::DMatrix<f64> {
        let n = self.v.ncols();
        let span = line.t[line.t.len() - 1] - line.t[0];
        nalgebra::DMatrix::from_fn(n, n, |j, k| {
            if j < k && (k - j) % 2 == 1 {
                (2 * j + 1) as f64 * 2.0 / span
            } else {
                0.0
            }
        })
    }

    /// `value` (time order) and the modes of `covariance` (of its coefficients in the smooth
    /// terms), each back in row order.
    fn carried(
        &self,
        line: &Timeline,
        value: &[f64],
        covariance: nalgebra::DMatrix<f64>,
    ) -> CarriedReading {
        let n = covariance.nrows();
        let eigen = nalgebra::SymmetricEigen::new(covariance);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        let largest = order
            .first()
            .map_or(0.0, |&j| eigen.eigenvalues[j].max(0.0));
        let (mut modes, mut sigma) = (Vec::new(), Vec::new());
        for &j in order
            .iter()
            .filter(|&&j| eigen.eigenvalues[j] > largest * 1e-12)
        {
            let mut u = eigen.eigenvectors.column(j).into_owned();
            // one sign for each mode, whatever the solver's
            let lead = u
                .iter()
                .copied()
                .fold(0.0_f64, |a, b| if b.abs() > a.abs() { b } else { a });
            if lead < 0.0 {
                u = -u;
            }
            let mode: Vec<f64> = (&self.v * u).iter().copied().collect();
            modes.push(line.unsorted(&mode));
            sigma.push(eigen.eigenvalues[j].sqrt());
        }
        CarriedReading {
            value: line.unsorted(value),
            errors: Modes { modes, sigma },
        }
    }
}

/// The most a smooth fit's residual may exceed the readings' noise, in mean square, for
/// [`carried_temperature`] to stand for the reading.
const HELD_TO_NOISE: f64 = 2.0;

/// The level at which a reading's fit must move for [`carried_temperature`] and
/// [`carried_rate`] to stand for it ([`Smooth::moves`]).
const MOVES_LEVEL: f64 = 1e-3;

/// The temperature of `x` for a fit that carries its smooth error, and that error's modes.
///
/// A thermometer's reading holds its noise, and an expansion α · (T − T_ref) of the reading
/// puts α times that noise into every row: a fit lowers α to shed it (on the twin's lag class
/// a lag and an encoder scale then took the expansion over, α down to −4.6 ppm/K against the
/// twin's 11.3). Here the temperature is the reading's least-squares fit in the smooth terms
/// ([`smooth_terms`] at its rate's window): the noise off the terms is gone, the noise in
/// them has the covariance σ² (VᵀV)⁻¹ of the fit, whose eigenvectors are the modes. (On the
/// twin's lag class the terms missed the temperature by at most 5e-4 K RMS where its noise
/// was 0.01 K; each mode's error over its σ had an RMS of 0.4-1.5.) None where the times span
/// nothing or the readings show no noise.
pub fn carried_temperature(line: &Timeline, x: &[f64]) -> Option<CarriedReading> {
    let smooth = Smooth::of(line, x)?;
    let value: Vec<f64> = (&smooth.v * &smooth.coef).iter().copied().collect();
    Some(smooth.carried(line, &value, smooth.covariance.clone()))
}

/// The rate of `x` for a fit that carries the rate's smooth error, and that error's modes:
/// the derivative in time of [`carried_temperature`]'s fit, whose coefficients' error makes
/// the rate's through the derivative of the terms (its covariance exact, the modes its
/// eigenvectors). The rate fitted over the window of least error ([`rate`]) cannot be carried
/// so: on the twin's lag class its error in the terms was up to 40 times what the
/// readings' noise made there (the quadratic's bend, misjudged from the width before), a
/// size no prior knows. None where [`carried_temperature`] is.
pub fn carried_rate(line: &Timeline, x: &[f64]) -> Option<CarriedReading> {
    let smooth = Smooth::of(line, x)?;
    let derivative = smooth.derivative(line);
    let rate: Vec<f64> = (&smooth.v * (&derivative * &smooth.coef))
        .iter()
        .copied()
        .collect();
    let covariance = &derivative * &smooth.covariance * derivative.transpose();
    Some(smooth.carried(line, &rate, covariance))
}

/// The readings' noise: the robust spread of each reading from the line through its two
/// neighbours (1.5 σ² for equal steps).
fn reading_noise(t: &[f64], x: &[f64]) -> f64 {
    let mut dev: Vec<f64> = (1..t.len().saturating_sub(1))
        .filter(|&i| t[i + 1] > t[i - 1])
        .map(|i| {
            let w = (t[i] - t[i - 1]) / (t[i + 1] - t[i - 1]);
            (x[i] - (x[i - 1] * (1.0 - w) + x[i + 1] * w)).abs()
        })
        .collect();
    if dev.is_empty() {
        return 0.0;
    }
    dev.sort_by(f64::total_cmp);
    1.4826 * dev[dev.len() / 2] / 1.5_f64.sqrt()
}

fn median_step(t: &[f64]) -> f64 {
    let mut steps: Vec<f64> = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    steps.sort_by(f64::total_cmp);
    steps.get(steps.len() / 2).copied().unwrap_or(0.0)
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// `lag(x, τ)` of one column, for any τ: its value and derivative by τ at every row, the
/// last few τ kept (a fit evaluates every row at one τ, then the next).
pub struct Lagged {
    line: Timeline,
    /// The reading in time order, and the reading and its rate in row order.
    x: Vec<f64>,
    reading: Vec<f64>,
    rate: Vec<f64>,
    kept: Mutex<Vec<(u64, Arc<Column>)>>,
}

/// (value, ∂/∂τ) per row.
pub type Column = Vec<(f64, f64)>;

/// How many τ a [`Lagged`] keeps.
const KEPT: usize = 4;

impl Lagged {
    /// The column `x` (row order) read at `line`'s times.
    pub fn new(line: Timeline, x: &[f64]) -> Lagged {
        let rate = rate(&line, x);
        Lagged {
            x: line.sorted(x),
            reading: x.to_vec(),
            line,
            rate,
            kept: Mutex::new(Vec::new()),
        }
    }

    /// (value, ∂/∂τ) at every row (row order) for time constant `tau`, seconds.
    pub fn at(&self, tau: f64) -> Arc<Column> {
        let key = tau.to_bits();
        let mut kept = self
            .kept
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(k) = kept.iter().position(|e| e.0 == key) {
            let hit = kept.remove(k);
            kept.push(hit.clone());
            return hit.1;
        }
        let made = Arc::new(self.made(tau));
        if kept.len() == KEPT {
            kept.remove(0);
        }
        kept.push((key, made.clone()));
        made
    }

    fn made(&self, tau: f64) -> Vec<(f64, f64)> {
        if tau >= 0.0 {
            return self
                .reading
                .iter()
                .zip(&self.rate)
                .map(|(x, r)| (x + tau * r, *r))
                .collect();
        }
        self.line.unsorted(&filtered(&self.line.t, &self.x, -tau))
    }
}

/// `x` filtered by a first-order lag of time constant `s` > 0 in time order, linear between
/// rows, from equilibrium with the first row: (value, ∂/∂τ = −∂/∂s) per row.
fn filtered(t: &[f64], x: &[f64], s: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(t.len());
    let (mut y, mut dy) = (x[0], 0.0);
    out.push((y, -dy));
    for k in 1..t.len() {
        let h = t[k] - t[k - 1];
        if h > 0.0 {
            let slope = (x[k] - x[k - 1]) / h;
            let a = (-h / s).exp();
            let gap = y - x[k - 1] + slope * s;
            // ∂a/∂s = a·h/s², zero once a is
            let da = if a > 0.0 { a * h / (s * s) } else { 0.0 };
            dy = -slope + (dy + slope) * a + gap * da;
            y = x[k] - slope * s + gap * a;
        }
        out.push((y, -dy));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn times(n: usize, step: f64) -> Vec<f64> {
        (0..n).map(|i| i as f64 * step).collect()
    }

    /// A warm-up T(t) = 20 + 2 (1 − cos(π t / 3000)): its rate is exact within the fit's
    /// truncation, with and without a noisy thermometer.
    #[test]
    fn rate_follows_a_warm_up_and_shrugs_off_noise() {
        let t = times(301, 10.0);
        let w = std::f64::consts::PI / 3000.0;
        let temp: Vec<f64> = t
            .iter()
            .map(|t| 20.0 + 2.0 * (1.0 - (w * t).cos()))
            .collect();
        let truth: Vec<f64> = t.iter().map(|t| 2.0 * w * (w * t).sin()).collect();
        let line = Timeline::new(&t).expect("times");
        let r = rate(&line, &temp);
        let worst = r
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        // the one-sided windows of the first and last rows: 0.05 % of the peak rate
        assert!(worst < 1e-6, "noiseless: worst error {worst:e} K/s");
        // 20 mK of noise (a deterministic scramble): the rate within a tenth of its peak 2.1e-3
        let noisy: Vec<f64> = temp
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.02 * (((i * 7919) % 101) as f64 / 50.0 - 1.0) * 1.7)
            .collect();
        let r = rate(&line, &noisy);
        let interior = 20..281;
        let err = rms(&interior.map(|i| r[i] - truth[i]).collect::<Vec<_>>());
        assert!(err < 1.1e-4, "noisy: rms error {err:e} K/s");
    }

    /// A thermometer that lags a part (τ > 0) and a part that lags it (τ < 0): `lag` gives
    /// the other's temperature, against the closed form of a first-order lag of a ramp.
    #[test]
    fn lag_undoes_and_makes_a_first_order_lag_of_a_ramp() {
        let t = times(200, 15.0);
        let (slope, tau) = (1e-3, 480.0);
        // the ramp's lag from equilibrium at 20 °C: y = 20 + s(t − τ(1 − e^(−t/τ)))
        let lagged: Vec<f64> = t
            .iter()
            .map(|t| 20.0 + slope * (t - tau * (1.0 - (-t / tau).exp())))
            .collect();
        let ramp: Vec<f64> = t.iter().map(|t| 20.0 + slope * t).collect();
        let line = Timeline::new(&t).expect("times");
        let part = Lagged::new(line.clone(), &lagged).at(tau);
        // within half a millikelvin from the tenth row on (the rate's fit over ±45 s misses
        // 0.3 % of the thermometer's fast-turning rate there)
        for i in 10..190 {
            assert!(
                (part[i].0 - ramp[i]).abs() < 5e-4,
                "row {i}: {} vs {}",
                part[i].0,
                ramp[i]
            );
        }
        let slow = Lagged::new(line, &ramp).at(-tau);
        for i in 0..200 {
            assert!((slow[i].0 - lagged[i]).abs() < 1e-12, "row {i}");
        }
    }

    /// ∂/∂τ against central differences on both sides of 0.
    #[test]
    fn lag_derivatives_are_exact() {
        let t: Vec<f64> = (0..80_u32)
            .map(|i| f64::from(i) * 13.0 + f64::from(i % 3))
            .collect();
        let x: Vec<f64> = t
            .iter()
            .map(|t| 20.0 + (t / 400.0).sin() + 1e-3 * t)
            .collect();
        let lag = Lagged::new(Timeline::new(&t).expect("times"), &x);
        for tau in [-900.0, -30.0, 45.0, 700.0] {
            let h = 1e-3;
            let (up, down, at) = (lag.at(tau + h), lag.at(tau - h), lag.at(tau));
            for i in 0..t.len() {
                let fd = (up[i].0 - down[i].0) / (2.0 * h);
                assert!(
                    (at[i].1 - fd).abs() < 1e-7,
                    "τ {tau}, row {i}: {} vs {fd}",
                    at[i].1
                );
            }
        }
    }

    /// The carried temperature and rate of a noisy warm-up (a lagged thermometer's swing,
    /// 20 min of 6 s readings with 10 mK of Gaussian noise, 200 draws): each mode's error
    /// against the true curve, over its σ, has an RMS of about 1 (the modes' priors are what
    /// the error is), and the fit leaves a small fraction of the raw noise in the temperature.
    #[test]
    fn carried_modes_are_as_large_as_the_error_they_carry() {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        let t = times(200, 6.0);
        let (w, tau) = (2.0 * std::f64::consts::PI / 7200.0, 900.0);
        // 20 − 3 cos(w t) seen through a first-order lag of τ from equilibrium at t = 0
        let (wt, den) = (w * tau, 1.0 + (w * tau).powi(2));
        let curve = |t: f64| {
            20.0 - 3.0 * ((w * t).cos() + wt * (w * t).sin()) / den
                - 3.0 * wt * wt / den * (-t / tau).exp()
        };
        let slope = |t: f64| (curve(t + 1e-3) - curve(t - 1e-3)) / 2e-3;
        let truth: Vec<f64> = t.iter().map(|&t| curve(t)).collect();
        let rates: Vec<f64> = t.iter().map(|&t| slope(t)).collect();
        let line = Timeline::new(&t).expect("times");
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let noise = rand_distr::Normal::new(0.0, 0.01).expect("normal");
        let (mut z_temp, mut z_rate, mut left) = (Vec::new(), Vec::new(), Vec::new());
        // a mode's coefficient in an error: the modes are orthogonal in the terms, so the
        // least-squares fit of the error on all modes at once
        let coefficients = |modes: &[Vec<f64>], e: &[f64]| -> Vec<f64> {
            let a = nalgebra::DMatrix::from_fn(e.len(), modes.len(), |i, k| modes[k][i]);
            let b = nalgebra::DVector::from_column_slice(e);
            let x = (a.transpose() * &a).try_inverse().expect("modes") * a.transpose() * b;
            x.iter().copied().collect()
        };
        for _ in 0..200 {
            let read: Vec<f64> = truth.iter().map(|v| v + noise.sample(&mut rng)).collect();
            let temp = carried_temperature(&line, &read).expect("a carried temperature");
            let e: Vec<f64> = temp.value.iter().zip(&truth).map(|(a, b)| a - b).collect();
            left.push(rms(&e));
            for (c, s) in coefficients(&temp.errors.modes, &e)
                .iter()
                .zip(&temp.errors.sigma)
            {
                z_temp.push(c / s);
            }
            let rate = carried_rate(&line, &read).expect("a carried rate");
            let e: Vec<f64> = rate.value.iter().zip(&rates).map(|(a, b)| a - b).collect();
            for (c, s) in coefficients(&rate.errors.modes, &e)
                .iter()
                .zip(&rate.errors.sigma)
            {
                z_rate.push(c / s);
            }
        }
        let (zt, zr) = (rms(&z_temp), rms(&z_rate));
        assert!(
            (0.85..1.15).contains(&zt),
            "temperature's modes: RMS of z {zt}"
        );
        assert!((0.85..1.15).contains(&zr), "rate's modes: RMS of z {zr}");
        let kept = rms(&left) / 0.01;
        assert!(
            kept < 0.35,
            "the carried temperature keeps {kept} of the readings' noise"
        );
    }

    /// A temperature set in steps is not what smooth terms hold: no carried temperature or
    /// rate (the expansion then reads the thermometer itself).
    #[test]
    fn a_stepped_temperature_is_not_carried() {
        let t = times(200, 6.0);
        let read: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                20.0 + (t / 300.0).floor() + 0.01 * ((i * 7919 % 101) as f64 / 50.0 - 1.0)
            })
            .collect();
        let line = Timeline::new(&t).expect("times");
        assert!(carried_temperature(&line, &read).is_none());
        assert!(carried_rate(&line, &read).is_none());
    }

    #[test]
    fn too_few_times_is_an_error() {
        assert_eq!(
            Timeline::new(&[0.0, 0.0, 5.0]).err(),
            Some(MemoryError::TooFewTimes(2))
        );
        assert_eq!(
            Timeline::new(&[0.0, f64::NAN, 5.0]).err(),
            Some(MemoryError::BadTime(1))
        );
    }
}
