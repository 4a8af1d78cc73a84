//! What a residual follows: the residual of each instrument direction (weighted by its σ)
//! against a dictionary of candidate explanations, the campaign's covariate columns, the drive
//! forces, time and low-order workspace polynomials of the TCP. The best single term (the
//! first step of orthogonal matching pursuit) is the pointer an engineer gets when no effect of
//! the library explains the residual: "the lt q1 residual follows approach_q1, r = 0.93".

use crate::campaign::Campaign;
use crate::geometry;
use crate::obs::RowValue;
use crate::params::{Model, Params};
use std::collections::BTreeMap;

/// A workspace term of the dictionary: a monomial of the nominal TCP (x, y).
type Monomial = fn(f64, f64) -> f64;

/// Fewest rows of a direction worth a correlation.
const MIN_ROWS: usize = 8;

/// Poses on each side of a thermometer reading whose trend its noise is measured from
/// ([`reading_noise`]).
const TREND_HALF_WINDOW: usize = 4;

/// A thermometer points at a direction's residual only where its readings there spread over
/// more than this many times its own noise ([`reading_noise`]).
const THERMOMETER_SPAN: f64 = 3.0;

/// A term of the dictionary: its values at every pose, and the noise of a thermometer's
/// readings (0 for the other terms).
struct Column {
    name: String,
    values: Vec<f64>,
    noise: f64,
}

/// A term of the dictionary that the residual follows.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Pointer {
    /// The term: a covariate name, `f1`..`f4`, `t`, or a polynomial (`x`, `y`, `x^2`, `x*y`,
    /// `y^2`, TCP in mm).
    pub feature: String,
    /// The instrument and direction whose residual follows it.
    pub instrument: String,
    pub direction: String,
    /// Pearson correlation of the weighted residual with the term.
    pub r: f64,
    /// Fraction of that direction's χ² a linear fit of the term removes (r²).
    pub explained: f64,
    /// Terms the same direction follows exactly as much (one column under two names: a
    /// follower moves with its drive).
    pub ties: Vec<String>,
    /// The next best terms.
    pub also: Vec<Term>,
}

/// A term of the dictionary and how much a direction's residual follows it.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Term {
    pub feature: String,
    pub instrument: String,
    pub direction: String,
    /// Pearson correlation of the weighted residual with the term.
    pub r: f64,
}

/// Where each pose of a campaign is, for maps and workspace terms: the nominal forward model
/// of its (q1, q4), mm (NaN where it cannot be solved: such a pose is left off a plot).
pub fn nominal_tcp(campaign: &Campaign) -> Vec<(f64, f64)> {
    let nominal = Params::nominal();
    campaign
        .poses
        .iter()
        .map(|p| {
            geometry::fgm(&nominal, Model::M29, p.q[0], p.q[3])
                .map_or((f64::NAN, f64::NAN), |s| (s.x(), s.y()))
        })
        .collect()
}

/// The dictionary's terms at every pose of a campaign, a thermometer's (`temp_*`, the spec's
/// temperatures) with the noise of its readings.
fn dictionary(campaign: &Campaign) -> Vec<Column> {
    let mut out: Vec<Column> = Vec::new();
    for (k, name) in campaign.covariate_names.iter().enumerate() {
        let values: Vec<f64> = campaign
            .poses
            .iter()
            .map(|p| p.covariates.get(k).copied().flatten().unwrap_or(f64::NAN))
            .collect();
        let noise = if name.starts_with("temp_") {
            reading_noise(campaign, &values)
        } else {
            0.0
        };
        out.push(Column {
            name: name.clone(),
            values,
            noise,
        });
    }
    let mut push = |name: String, values: Vec<f64>| {
        out.push(Column {
            name,
            values,
            noise: 0.0,
        });
    };
    for j in 0..4 {
        push(
            format!("f{}", j + 1),
            campaign.poses.iter().map(|p| p.f[j]).collect(),
        );
    }
    push("t".to_owned(), campaign.poses.iter().map(|p| p.t).collect());
    // direction of motion, travel since reversal, time: what lost motion, friction and
    // drift follow
    for (name, values) in campaign
        .derived_covariates()
        .into_iter()
        .filter(|d| d.0 != "t_run" && campaign.covariate_index(&d.0).is_none())
    {
        push(name, values);
    }
    let tcp = nominal_tcp(campaign);
    let poly: [(&str, Monomial); 5] = [
        ("x", |x, _| x),
        ("y", |_, y| y),
        ("x^2", |x, _| x * x),
        ("x*y", |x, y| x * y),
        ("y^2", |_, y| y * y),
    ];
    for (name, f) in poly {
        push(name.to_owned(), tcp.iter().map(|&(x, y)| f(x, y)).collect());
    }
    out
}

/// The noise of a thermometer's readings: their RMS about the straight line in time through
/// each reading's neighbours in its setup (less the line's two degrees of freedom). A reading
/// is the slow temperature plus the sensor's noise, and a model that reads it (thermal
/// expansion) carries that noise into its residual, times the expansion's gain: where the
/// temperature hardly moves over a direction's rows (a tracker's 44 poses over two minutes:
/// 0.03 K, against a sensor's 0.01 K) the residual follows the reading closely (r = 0.7) with
/// nothing missing from the model, and no effect could be told from the sensor's noise there.
fn reading_noise(campaign: &Campaign, readings: &[f64]) -> f64 {
    let trend = trend(campaign, readings);
    let d: Vec<f64> = readings
        .iter()
        .zip(&trend)
        .map(|(r, t)| r - t)
        .filter(|v| v.is_finite())
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    let window = (2 * TREND_HALF_WINDOW + 1) as f64;
    let ms = d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64;
    (ms * window / (window - 2.0)).sqrt()
}

/// Each reading's straight line in time through its setup's neighbouring poses, at its time.
fn trend(campaign: &Campaign, readings: &[f64]) -> Vec<f64> {
    let mut setups: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
    for (i, p) in campaign.poses.iter().enumerate() {
        setups.entry(p.setup.as_str()).or_default().push(i);
    }
    let mut out = readings.to_vec();
    for members in setups.values() {
        for (j, &i) in members.iter().enumerate() {
            let lo = j.saturating_sub(TREND_HALF_WINDOW);
            let hi = (j + TREND_HALF_WINDOW + 1).min(members.len());
            let window = members[lo..hi]
                .iter()
                .map(|&k| (campaign.poses[k].t, readings[k]))
                .filter(|(t, v)| t.is_finite() && v.is_finite());
            if readings[i].is_finite() {
                if let Some(v) = line_at(window, campaign.poses[i].t) {
                    out[i] = v;
                }
            }
        }
    }
    out
}

/// The least-squares line through `points` (t, v) at `t`; their mean where t does not vary;
/// None without points. Passes over the points three times rather than collect them: it
/// runs once per pose of every thermometer column.
fn line_at(points: impl Iterator<Item = (f64, f64)> + Clone, t: f64) -> Option<f64> {
    let n = points.clone().count() as f64;
    if n == 0.0 {
        return None;
    }
    let (mt, mv) = points
        .clone()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (stt, stv) = points.fold((0.0, 0.0), |(a, b), (x, y)| {
        (a + (x - mt).powi(2), b + (x - mt) * (y - mv))
    });
    Some(if stt > 0.0 {
        mv + stv / stt * (t - mt)
    } else {
        mv
    })
}

/// Pearson correlation over the pairs where both are finite; None if either is constant.
fn correlation(a: &[f64], b: &[f64]) -> Option<f64> {
    let pairs: Vec<(f64, f64)> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| (*x, *y))
        .collect();
    if pairs.len() < MIN_ROWS {
        return None;
    }
    let n = pairs.len() as f64;
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(sa, sb), (x, y)| (sa + x / n, sb + y / n));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in &pairs {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    let scale_a = pairs.iter().map(|p| p.0.abs()).fold(0.0, f64::max);
    // a term constant to round-off is no explanation
    if !(saa > 1e-18 * scale_a * scale_a * n) || !(sbb > 0.0) {
        return None;
    }
    Some(sab / (saa * sbb).sqrt())
}

/// The standard deviation of the finite values.
fn spread(v: &[f64]) -> f64 {
    let f: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if f.len() < 2 {
        return 0.0;
    }
    let n = f.len() as f64;
    let m = f.iter().sum::<f64>() / n;
    (f.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

/// Every (term, instrument, direction) correlation, scored by the χ² it would explain.
fn scores(campaign: &Campaign, rows: &[RowValue], only: Option<&[&str]>) -> Vec<Scored> {
    let dict = dictionary(campaign);
    let mut groups: BTreeMap<(String, String), Vec<&RowValue>> = BTreeMap::new();
    for r in rows {
        groups
            .entry((r.instrument.as_str().to_owned(), r.direction.to_string()))
            .or_default()
            .push(r);
    }
    let mut out = Vec::new();
    for ((inst, dir), g) in &groups {
        if g.len() < MIN_ROWS {
            continue;
        }
        let z: Vec<f64> = g.iter().map(|r| r.value / r.sigma).collect();
        let chi2: f64 = z.iter().map(|v| v * v).sum();
        for column in &dict {
            if only.is_some_and(|o| !o.contains(&column.name.as_str())) {
                continue;
            }
            let v: Vec<f64> = g.iter().map(|r| column.values[r.pose]).collect();
            if column.noise > 0.0 && spread(&v) <= THERMOMETER_SPAN * column.noise {
                continue;
            }
            if let Some(r) = correlation(&v, &z) {
                out.push(Scored {
                    rows: g.len(),
                    feature: column.name.clone(),
                    instrument: inst.clone(),
                    direction: dir.clone(),
                    r,
                    explained_chi2: r * r * chi2,
                });
            }
        }
    }
    out.sort_by(|a, b| b.explained_chi2.total_cmp(&a.explained_chi2));
    out
}

struct Scored {
    rows: usize,
    feature: String,
    instrument: String,
    direction: String,
    r: f64,
    explained_chi2: f64,
}

fn pointer(s: &[Scored]) -> Option<Pointer> {
    let best = s.first()?;
    let ties: Vec<String> = s
        .iter()
        .skip(1)
        .filter(|x| x.instrument == best.instrument && x.direction == best.direction)
        .filter(|x| (x.r.abs() - best.r.abs()).abs() < 1e-9)
        .map(|x| x.feature.clone())
        .collect();
    Some(Pointer {
        ties,
        feature: best.feature.clone(),
        instrument: best.instrument.clone(),
        direction: best.direction.clone(),
        r: best.r,
        explained: best.r * best.r,
        also: s
            .iter()
            .skip(1)
            .take(4)
            .map(|x| Term {
                feature: x.feature.clone(),
                instrument: x.instrument.clone(),
                direction: x.direction.clone(),
                r: x.r,
            })
            .collect(),
    })
}

/// The dictionary test of a residual: is any term followed more than noise would?
#[derive(Clone, Debug, serde::Serialize)]
pub struct Structure {
    /// The best term and the direction that follows it (None: nothing to correlate).
    pub pointer: Option<Pointer>,
    /// F statistic of that term's linear fit, F(1, n − 2), and its p-value corrected for the
    /// number of (term, direction) pairs tried (Bonferroni).
    pub f_statistic: f64,
    pub p_value: f64,
    pub tests: usize,
    /// χ² the term removes from its direction (its evidence against an effect's Δχ²).
    pub explained_chi2: f64,
    /// Rows of that direction (for its information criterion).
    pub rows: usize,
}

/// Test the residual `rows` against the whole dictionary (each term in each instrument
/// direction): free of the noise's absolute level, since a correlation is.
pub fn structure(campaign: &Campaign, rows: &[RowValue]) -> Structure {
    let s = scores(campaign, rows, None);
    let tests = s.len();
    let Some(best) = s.first() else {
        return Structure {
            pointer: None,
            f_statistic: 0.0,
            p_value: 1.0,
            tests: 0,
            explained_chi2: 0.0,
            rows: 0,
        };
    };
    let n = best.rows as f64;
    let r2 = (best.r * best.r).min(1.0 - 1e-15);
    let f = r2 * (n - 2.0) / (1.0 - r2);
    let p = crate::stats::f_upper_tail(f, 1.0, n - 2.0);
    Structure {
        pointer: pointer(&s),
        f_statistic: f,
        p_value: (p * tests as f64).min(1.0),
        tests,
        explained_chi2: best.explained_chi2,
        rows: best.rows,
    }
}

/// The covariate among `names` the residual follows most (None if `names` is empty or none
/// varies).
pub fn follows(campaign: &Campaign, rows: &[RowValue], names: &[&str]) -> Option<Pointer> {
    if names.is_empty() {
        return None;
    }
    pointer(&scores(campaign, rows, Some(names)))
}
