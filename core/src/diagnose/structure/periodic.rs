//! Periodic structure in a residual: each instrument direction's weighted residual against
//! sine and cosine of each carrier's position, over pitches from a few millimetres to the
//! carrier's travel in the data (a periodogram). A scale's cyclic error, a ball screw's
//! pitch error or a guide's waviness follow a position with a period; a dictionary term
//! follows it only where the period happens to match. Like the dictionary's test, it rests on
//! no noise level: the statistic is the F of a two-term fit (sine and cosine, the phase
//! free) against the rest of the residual.
//!
//! Two things keep the pointer from misleading: carriers that move together on the rows
//! (`tied`) are named together, since their periods look alike there; and a period that the
//! direction's strongest dictionary covariate explains (a lost motion's `dir_q*` seen at the
//! setups' raster is a square wave, which has a period) is listed as an alias and passed over.

use crate::campaign::Campaign;
use crate::obs::{Direction, RowValue};
use nalgebra::{DMatrix, DVector};
use std::collections::BTreeMap;

/// Shortest pitch tried, mm: a few times the finest step of the designs.
pub const MIN_PITCH_MM: f64 = 5.0;
/// Frequencies per cycle over the travel: a phase drift of a quarter cycle between
/// neighbouring frequencies at the ends of the travel, so a period between two of them loses
/// little of its fit.
const OVERSAMPLING: f64 = 4.0;
/// A period is an alias of a dictionary term when the term, removed, takes more than half of
/// what the period explained with it.
const KEPT: f64 = 0.5;
/// Fewest rows of a direction worth a periodogram.
const MIN_ROWS: usize = 16;

/// Fraction of a period's fitted wave that another carrier's own sine and cosine must
/// reproduce on the same rows for the period to be that carrier's as well: the two carriers
/// move together there (a self-calibration line moves every carrier with the TCP, carriers 1
/// and 4 nearly as mirror images), and what tells their periods apart is the rest of the
/// wave, a fifth or less, which the calibrated geometry's share of the wave and any other
/// misfit shift from one carrier to the other.
pub const TIED: f64 = 0.8;

/// The strongest period found in a residual.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Periodic {
    /// Carrier 1..4 whose position the residual follows (the best of a tie).
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
    /// The other carriers whose positions the same wave follows as well on these rows (they
    /// move together on these setups): the period may be any of theirs. Best first.
    pub tied: Vec<TiedCarrier>,
    /// Stronger periods left out: each follows a dictionary term (the alias of a lost
    /// motion, which `dir_q*` follows) and is not significant once the term is removed.
    pub aliases: Vec<Alias>,
}

/// A carrier whose position follows a period's wave as well as the named carrier's does.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TiedCarrier {
    /// Carrier 1..4.
    pub carrier: usize,
    /// The pitch in this carrier's position, mm (the carriers move at different rates).
    pub pitch_mm: f64,
    /// Fraction of the named carrier's fitted wave this carrier's sine and cosine reproduce.
    pub reproduced: f64,
}

/// A period left out because a dictionary term explains it.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Alias {
    pub carrier: usize,
    pub pitch_mm: f64,
    pub instrument: String,
    pub direction: String,
    /// The term (a covariate, or `dir_q*`, `travel_q*` of the campaign's motion).
    pub term: String,
    /// The period's p-value once the term is removed from its direction's residual.
    pub p_value_without: f64,
}

/// One direction's rows: weighted residual and each carrier's position.
#[derive(Clone)]
struct Series {
    instrument: String,
    direction: String,
    z: Vec<f64>,
    q: [Vec<f64>; 4],
    sigma_rms: f64,
    /// Index of each of its rows in the residual.
    members: Vec<usize>,
}

/// A direction's rows the periodogram reads at most: beyond, every k-th row in pose order.
/// A scale's period that matters stands out of twenty thousand rows by far (its F grows with
/// the rows), while every row costs each of the thousands of pitches tried: on 10⁵ poses the
/// scan was half the diagnosis.
const MAX_SERIES_ROWS: usize = 20_000;

/// The period the diagnosis reports, tested at `level` (None: no direction has enough rows):
/// the strongest period of the residual `rows` that no dictionary covariate explains (a period that the covariate its direction
/// follows most leaves non-significant once removed is an alias, listed and passed over),
/// with every carrier whose position follows it as well.
pub fn periodogram(campaign: &Campaign, rows: &[RowValue], level: f64) -> Option<Periodic> {
    let mut series = series(campaign, rows);
    let mut scans: Vec<Scan> = series.iter().map(Scan::of).collect();
    let mut cleaned = vec![false; series.len()];
    let mut aliases = Vec::new();
    let (i, mut best) = loop {
        let (i, best) = strongest(&scans)?;
        if cleaned[i] {
            break (i, best);
        }
        cleaned[i] = true;
        let Some((alias, z)) = alias_of(campaign, rows, &series[i], &best, level) else {
            break (i, best);
        };
        aliases.push(alias);
        series[i].z = z;
        scans[i] = Scan::of(&series[i]);
    };
    best.tied = tied(&series[i], &best);
    best.aliases = aliases;
    Some(best)
}

/// The strongest period over every direction and carrier scanned, with its direction's
/// index; its p-value corrected for every pitch tried.
fn strongest(scans: &[Scan]) -> Option<(usize, Periodic)> {
    let tests: usize = scans.iter().map(|s| s.tests).sum();
    let (i, best) = scans
        .iter()
        .enumerate()
        .flat_map(|(i, s)| s.best.iter().flatten().map(move |p| (i, p)))
        .max_by(|a, b| a.1.f_statistic.total_cmp(&b.1.f_statistic))?;
    let mut best = best.clone();
    best.tests = tests;
    best.p_value = (best.p_value * tests as f64).min(1.0);
    Some((i, best))
}

/// One direction's best period of each carrier and the pitches tried.
struct Scan {
    best: [Option<Periodic>; 4],
    tests: usize,
}

impl Scan {
    /// The four carriers scanned side by side, one thread each (each scan reads its own
    /// positions and sums its own grid: the same numbers as one after the other; on 10⁵
    /// poses the scans on one core were a fifth of the diagnosis).
    fn of(s: &Series) -> Scan {
        let found: [Option<(Periodic, usize)>; 4] = std::thread::scope(|scope| {
            let scans: [_; 4] =
                std::array::from_fn(|carrier| scope.spawn(move || scan(s, carrier)));
            // a panic in a scan is a bug: it goes on in this thread
            scans.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
        });
        let tests = found.iter().flatten().map(|f| f.1).sum();
        Scan {
            best: found.map(|f| f.map(|f| f.0)),
            tests,
        }
    }
}

/// The rows grouped by instrument and direction, in pose order. Forces and a 2-D
/// instrument's compatibility rows are left out: they follow the loop's stiffness and the
/// elastic model's last fraction of a µm, which a regular grid of poses aliases into short
/// periods; a scale's error shows in the TCP and follower rows.
fn series(campaign: &Campaign, rows: &[RowValue]) -> Vec<Series> {
    let mut groups: BTreeMap<(String, String), Vec<usize>> = BTreeMap::new();
    let periodic = |r: &RowValue| {
        !r.direction.is_force() && !matches!(r.direction, Direction::Compat(_)) && r.sigma > 0.0
    };
    for (i, r) in rows.iter().enumerate().filter(|(_, r)| periodic(r)) {
        groups
            .entry((r.instrument.as_str().to_owned(), r.direction.to_string()))
            .or_default()
            .push(i);
    }
    groups
        .into_iter()
        .filter(|(_, g)| g.len() >= MIN_ROWS)
        .map(|((instrument, direction), members)| {
            let stride = members.len().div_ceil(MAX_SERIES_ROWS);
            let members: Vec<usize> = members.into_iter().step_by(stride).collect();
            let g: Vec<&RowValue> = members.iter().map(|&i| &rows[i]).collect();
            let q =
                std::array::from_fn(|j| g.iter().map(|r| campaign.poses[r.pose].q[j]).collect());
            let var: f64 = g.iter().map(|r| r.sigma * r.sigma).sum::<f64>() / g.len() as f64;
            Series {
                instrument,
                direction,
                z: g.iter().map(|r| r.value / r.sigma).collect(),
                q,
                sigma_rms: var.sqrt(),
                members,
            }
        })
        .collect()
}

/// The frequency grid of a carrier's positions (first frequency, step, count; 1/mm): from
/// one cycle over its travel to [`MIN_PITCH_MM`] (None: it travels too little).
fn grid(q: &[f64]) -> Option<(f64, f64, usize)> {
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
    let f0 = 1.0 / travel;
    let n_freq = crate::convert::floor_count((1.0 / MIN_PITCH_MM - f0) / step) + 1;
    Some((f0, step, n_freq))
}

/// The best two-term fit of `z` over the frequency grid of positions `q`: its frequency
/// (1/mm) and (R², a, b), with the number of frequencies tried.
fn best_fit(z: &[f64], q: &[f64]) -> Option<(f64, (f64, f64, f64), usize)> {
    let (f0, step, n_freq) = grid(q)?;
    let sums = Sums::over(z, q, (f0, step, n_freq));
    let n = z.len() as f64;
    let (mut best_k, mut best) = (0, (0.0, 0.0, 0.0));
    for k in 0..n_freq {
        let fit = sums.fit(k, n);
        if fit.0 > best.0 {
            (best_k, best) = (k, fit);
        }
    }
    Some((f0 + best_k as f64 * step, best, n_freq))
}

/// The best pitch of carrier `carrier` for one direction, with the number of pitches tried.
fn scan(s: &Series, carrier: usize) -> Option<(Periodic, usize)> {
    let (freq, (r2, a, b), n_freq) = best_fit(&s.z, &s.q[carrier])?;
    let n = s.z.len() as f64;
    let r2 = r2.min(1.0 - 1e-15);
    let f = (r2 / 2.0) / ((1.0 - r2) / (n - 3.0));
    let found = Periodic {
        carrier: carrier + 1,
        pitch_mm: 1.0 / freq,
        instrument: s.instrument.clone(),
        direction: s.direction.clone(),
        amplitude: a.hypot(b) * s.sigma_rms,
        explained: r2,
        f_statistic: f,
        p_value: crate::stats::f_upper_tail(f, 2.0, n - 3.0),
        tests: 0,
        tied: Vec::new(),
        aliases: Vec::new(),
    };
    Some((found, n_freq))
}

/// The fitted wave of period `p` on its direction's rows (centred): a · sin + b · cos.
fn wave(s: &Series, p: &Periodic) -> Vec<f64> {
    let q = &s.q[p.carrier - 1];
    let sums = Sums::over(&s.z, q, (1.0 / p.pitch_mm, 0.0, 1));
    let (_, a, b) = sums.fit(0, s.z.len() as f64);
    let tau = std::f64::consts::TAU;
    let raw: Vec<f64> = q
        .iter()
        .map(|&qi| {
            let (sn, cs) = (tau * qi / p.pitch_mm).sin_cos();
            a * sn + b * cs
        })
        .collect();
    let mean = raw.iter().sum::<f64>() / raw.len() as f64;
    raw.into_iter().map(|v| v - mean).collect()
}

/// The carriers other than `p`'s whose own sine and cosine (at their best pitch) reproduce
/// at least [`TIED`] of `p`'s fitted wave on its rows, best first.
fn tied(s: &Series, p: &Periodic) -> Vec<TiedCarrier> {
    let w = wave(s, p);
    let mut out: Vec<TiedCarrier> = (0..4)
        .filter(|&c| c + 1 != p.carrier)
        .filter_map(|c| {
            let (freq, (r2, _, _), _) = best_fit(&w, &s.q[c])?;
            (r2 >= TIED).then(|| TiedCarrier {
                carrier: c + 1,
                pitch_mm: 1.0 / freq,
                reproduced: r2,
            })
        })
        .collect();
    out.sort_by(|a, b| b.reproduced.total_cmp(&a.reproduced));
    out
}

/// Where period `p` of direction `s` is an alias: the covariate the direction's residual
/// follows most (of the file's and the motion's: `dir_q*`, `travel_q*`), and the residual
/// less its linear fit, when the period is no longer significant at `level` without it.
fn alias_of(
    campaign: &Campaign,
    rows: &[RowValue],
    s: &Series,
    p: &Periodic,
    level: f64,
) -> Option<(Alias, Vec<f64>)> {
    let members: Vec<RowValue> = s.members.iter().map(|&i| rows[i].clone()).collect();
    let mut names: Vec<String> = campaign.covariate_names.clone();
    names.extend(campaign.derived_covariates().into_iter().map(|d| d.0));
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let term = super::sparse::follows(campaign, &members, &names)?;
    let values = campaign.covariate(&term.feature)?;
    let x: Vec<f64> = members
        .iter()
        .map(|r| values.get(r.pose).copied().flatten())
        .collect::<Option<_>>()?;
    let setups: Vec<&str> = members
        .iter()
        .map(|r| campaign.poses[r.pose].setup.as_str())
        .collect();
    let q = &s.q[p.carrier - 1];
    let (z, fitted) = less_term(&s.z, &x, q, &setups);
    let n = z.len() as f64;
    let (r2, _, _) = Sums::over(&z, q, (1.0 / p.pitch_mm, 0.0, 1)).fit(0, n);
    let r2 = r2.min(1.0 - 1e-15);
    // the term's coefficients gone too
    let dof = n - 3.0 - fitted as f64;
    let f = (r2 / 2.0) / ((1.0 - r2) / dof);
    let p_without = (crate::stats::f_upper_tail(f, 2.0, dof) * p.tests as f64).min(1.0);
    // what the period still explains, against what it explained (its share of the χ² times it)
    let chi2 = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
    let kept = r2 * chi2(&z) / (p.explained * chi2(&s.z));
    (p_without >= level || kept < KEPT).then(|| {
        let alias = Alias {
            carrier: p.carrier,
            pitch_mm: p.pitch_mm,
            instrument: p.instrument.clone(),
            direction: p.direction.clone(),
            term: term.feature,
            p_value_without: p_without,
        };
        (alias, z)
    })
}

/// `z` less the term `x` fitted in each setup apart, with its effect varying linearly along
/// the setup's path in the carrier's position `q` (a term acts on a direction through the
/// machine's Jacobian, which changes along a line and from one line or mounting to the next):
/// per setup, z on (1, x, q, x·q). Also the number of coefficients fitted.
fn less_term(z: &[f64], x: &[f64], q: &[f64], setups: &[&str]) -> (Vec<f64>, usize) {
    let mut out = z.to_vec();
    let mut fitted = 0;
    let mut names: Vec<&str> = setups.to_vec();
    names.sort_unstable();
    names.dedup();
    for name in names {
        let idx: Vec<usize> = (0..z.len()).filter(|&i| setups[i] == name).collect();
        let m = idx.len() as f64;
        let mq = idx.iter().map(|&i| q[i]).sum::<f64>() / m;
        let mx = idx.iter().map(|&i| x[i]).sum::<f64>() / m;
        let a = DMatrix::from_fn(idx.len(), 4, |r, c| {
            let (xi, qi) = (x[idx[r]] - mx, q[idx[r]] - mq);
            [1.0, xi, qi, xi * qi][c]
        });
        let b = DVector::from_iterator(idx.len(), idx.iter().map(|&i| z[i]));
        let svd = a.svd(true, true);
        let tol = 1e-9 * svd.singular_values.max();
        fitted += svd.rank(tol);
        let Ok(coef) = svd.solve(&b, tol) else {
            continue;
        };
        let fit = DMatrix::from_fn(idx.len(), 4, |r, c| {
            let (xi, qi) = (x[idx[r]] - mx, q[idx[r]] - mq);
            [1.0, xi, qi, xi * qi][c]
        }) * coef;
        for (r, &i) in idx.iter().enumerate() {
            out[i] = z[i] - fit[r];
        }
    }
    (out, fitted)
}

/// Rows whose phasors [`Sums::over`] turns side by side: one row's turns wait on each other,
/// several rows' overlap (each frequency's sums still take the rows in order, so the sums are
/// those of one row at a time to the bit).
const LANES: usize = 4;

/// One row's phasor on the frequency grid: its value at the current frequency, and the turn
/// of one grid step.
struct Phasor {
    z: f64,
    s: f64,
    c: f64,
    ds: f64,
    dc: f64,
}

impl Phasor {
    /// The row (z, q) at the grid's first frequency (`f0`, step `df`).
    fn at((z, q): (f64, f64), (f0, df, _): (f64, f64, usize)) -> Phasor {
        let tau = std::f64::consts::TAU;
        let (s, c) = (tau * f0 * q).sin_cos();
        let (ds, dc) = (tau * df * q).sin_cos();
        Phasor { z, s, c, ds, dc }
    }

    /// Add the row to a frequency's sums `a`, turned one step first where `turn`.
    fn add_to(&mut self, a: &mut [f64; 7], turn: bool) {
        if turn {
            (self.s, self.c) = (
                self.s * self.dc + self.c * self.ds,
                self.c * self.dc - self.s * self.ds,
            );
        }
        let (s, c, z) = (self.s, self.c, self.z);
        a[0] += s;
        a[1] += c;
        a[2] += s * s;
        a[3] += c * c;
        a[4] += s * c;
        a[5] += z * s;
        a[6] += z * c;
    }
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
    fn over(z: &[f64], q: &[f64], grid: (f64, f64, usize)) -> Sums {
        let mut acc = vec![[0.0; 7]; grid.2];
        let n = z.len().min(q.len());
        let whole = n - n % LANES;
        for (zs, qs) in z[..whole]
            .chunks_exact(LANES)
            .zip(q[..whole].chunks_exact(LANES))
        {
            let mut lanes: [Phasor; LANES] =
                std::array::from_fn(|l| Phasor::at((zs[l], qs[l]), grid));
            for (k, a) in acc.iter_mut().enumerate() {
                for p in &mut lanes {
                    p.add_to(a, k > 0);
                }
            }
        }
        for row in z[whole..n].iter().copied().zip(q[whole..n].iter().copied()) {
            let mut p = Phasor::at(row, grid);
            for (k, a) in acc.iter_mut().enumerate() {
                p.add_to(a, k > 0);
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
