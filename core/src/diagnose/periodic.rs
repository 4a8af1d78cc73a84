//! Periodic structure in a residual: each instrument direction's weighted residual against
//! sine and cosine of each carrier's position, over pitches from a few millimetres to the
//! carrier's travel in the data (a periodogram). A scale's cyclic error, a ball screw's
//! pitch error or a guide's waviness follow a position with a period; a dictionary term
//! follows it only where the period happens to match. Like the dictionary's test, it rests on
//! no noise level: the statistic is the F of a two-term fit (sine and cosine, the phase
//! free) against the rest of the residual.

use crate::campaign::Campaign;
use crate::obs::{Direction, RowValue};
use std::collections::BTreeMap;

/// Shortest pitch tried, mm: a few times the finest step of the designs.
pub const MIN_PITCH_MM: f64 = 5.0;
/// Frequencies per cycle over the travel: a phase drift of a quarter cycle between
/// neighbouring frequencies at the ends of the travel, so a period between two of them loses
/// little of its fit.
const OVERSAMPLING: f64 = 4.0;
/// Fewest rows of a direction worth a periodogram.
const MIN_ROWS: usize = 16;

/// The strongest period found in a residual.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Periodic {
    /// Carrier 1..4 whose position the residual follows.
    pub carrier: usize,
    pub pitch_mm: f64,
    pub instrument: String,
    pub direction: String,
    /// Amplitude of the fitted sine (mm, or rad for ψ, N for a force): its size in the
    /// direction's own unit, √(a² + b²) times the rows' RMS σ.
    pub amplitude: f64,
    /// Fraction of the direction's residual variance the period removes.
    pub explained: f64,
    /// F(2, n − 3) of the fit and its p-value corrected for every (direction, carrier,
    /// pitch) tried (Bonferroni).
    pub f_statistic: f64,
    pub p_value: f64,
    pub tests: usize,
}

/// One direction's rows: weighted residual and each carrier's position.
struct Series {
    instrument: String,
    direction: String,
    z: Vec<f64>,
    q: [Vec<f64>; 4],
    sigma_rms: f64,
}

/// The strongest period of the residual `rows` (None: no direction has enough rows).
pub fn periodogram(campaign: &Campaign, rows: &[RowValue]) -> Option<Periodic> {
    let mut best: Option<Periodic> = None;
    let mut tests = 0usize;
    for s in series(campaign, rows) {
        for carrier in 0..4 {
            let Some((found, n)) = scan(&s, carrier) else {
                continue;
            };
            tests += n;
            if best
                .as_ref()
                .is_none_or(|b| found.f_statistic > b.f_statistic)
            {
                best = Some(found);
            }
        }
    }
    best.map(|mut b| {
        b.tests = tests;
        b.p_value = (b.p_value * tests as f64).min(1.0);
        b
    })
}

/// The rows grouped by instrument and direction, in pose order. Forces and a 2-D
/// instrument's compatibility rows are left out: they follow the loop's stiffness and the
/// elastic model's last fraction of a µm, which a regular grid of poses aliases into short
/// periods; a scale's error shows in the TCP and follower rows.
fn series(campaign: &Campaign, rows: &[RowValue]) -> Vec<Series> {
    let mut groups: BTreeMap<(String, String), Vec<&RowValue>> = BTreeMap::new();
    let periodic = |r: &&RowValue| {
        !r.direction.is_force() && !matches!(r.direction, Direction::Compat(_)) && r.sigma > 0.0
    };
    for r in rows.iter().filter(periodic) {
        groups
            .entry((r.instrument.as_str().to_owned(), r.direction.to_string()))
            .or_default()
            .push(r);
    }
    groups
        .into_iter()
        .filter(|(_, g)| g.len() >= MIN_ROWS)
        .map(|((instrument, direction), g)| {
            let q =
                std::array::from_fn(|j| g.iter().map(|r| campaign.poses[r.pose].q[j]).collect());
            let var: f64 = g.iter().map(|r| r.sigma * r.sigma).sum::<f64>() / g.len() as f64;
            Series {
                instrument,
                direction,
                z: g.iter().map(|r| r.value / r.sigma).collect(),
                q,
                sigma_rms: var.sqrt(),
            }
        })
        .collect()
}

/// The best pitch of carrier `carrier` for one direction, with the number of pitches tried.
fn scan(s: &Series, carrier: usize) -> Option<(Periodic, usize)> {
    let q = &s.q[carrier];
    let (lo, hi) = q
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let travel = hi - lo;
    if !(travel > 2.0 * MIN_PITCH_MM) {
        return None;
    }
    let step = 1.0 / (OVERSAMPLING * travel);
    let n_freq = crate::convert::floor_count((1.0 / MIN_PITCH_MM - 1.0 / travel) / step) + 1;
    let sums = Sums::over(&s.z, q, (1.0 / travel, step, n_freq));
    let n = s.z.len() as f64;
    let (mut best_k, mut best) = (0, (0.0, 0.0, 0.0));
    for k in 0..n_freq {
        let fit = sums.fit(k, n);
        if fit.0 > best.0 {
            (best_k, best) = (k, fit);
        }
    }
    let (r2, a, b) = best;
    let r2 = r2.min(1.0 - 1e-15);
    let f = (r2 / 2.0) / ((1.0 - r2) / (n - 3.0));
    let found = Periodic {
        carrier: carrier + 1,
        pitch_mm: 1.0 / (1.0 / travel + best_k as f64 * step),
        instrument: s.instrument.clone(),
        direction: s.direction.clone(),
        amplitude: a.hypot(b) * s.sigma_rms,
        explained: r2,
        f_statistic: f,
        p_value: crate::stats::f_upper_tail(f, 2.0, n - 3.0),
        tests: 0,
    };
    Some((found, n_freq))
}

/// Per frequency of a uniform grid: the sums a two-term fit (sine, cosine and an offset)
/// needs, accumulated row by row with each row's phasor turned by one step of the grid (no
/// sine evaluated per frequency).
struct Sums {
    /// s, c, ss, cc, sc, zs, zc per frequency.
    acc: Vec<[f64; 7]>,
    z_sum: f64,
    zz: f64,
}

impl Sums {
    fn over(z: &[f64], q: &[f64], (f0, df, n_freq): (f64, f64, usize)) -> Sums {
        let mut acc = vec![[0.0; 7]; n_freq];
        for (&zi, &qi) in z.iter().zip(q) {
            let tau = std::f64::consts::TAU;
            let (mut s, mut c) = (tau * f0 * qi).sin_cos();
            let (ds, dc) = (tau * df * qi).sin_cos();
            for (k, a) in acc.iter_mut().enumerate() {
                if k > 0 {
                    (s, c) = (s * dc + c * ds, c * dc - s * ds);
                }
                a[0] += s;
                a[1] += c;
                a[2] += s * s;
                a[3] += c * c;
                a[4] += s * c;
                a[5] += zi * s;
                a[6] += zi * c;
            }
        }
        Sums {
            acc,
            z_sum: z.iter().sum(),
            zz: z.iter().map(|v| v * v).sum(),
        }
    }

    /// R² of the fit of z on (1, sin, cos) at frequency `k` over the centred residual, and
    /// the sine's and cosine's coefficients.
    fn fit(&self, k: usize, n: f64) -> (f64, f64, f64) {
        let [s, c, ss, cc, sc, zs, zc] = self.acc[k];
        // centred: every sum less its mean's share
        let (ss, cc, sc) = (ss - s * s / n, cc - c * c / n, sc - s * c / n);
        let (zs, zc) = (zs - self.z_sum * s / n, zc - self.z_sum * c / n);
        let total = self.zz - self.z_sum * self.z_sum / n;
        let det = ss * cc - sc * sc;
        if !(det > 1e-12 * ss * cc) || !(total > 0.0) {
            return (0.0, 0.0, 0.0);
        }
        let a = (cc * zs - sc * zc) / det;
        let b = (ss * zc - sc * zs) / det;
        ((a * zs + b * zc) / total, a, b)
    }
}
