//! Are neighbours alike? Along a setup's path (its poses in the order they were measured),
//! the weighted residuals of one instrument direction are independent if only noise is
//! left; a missing smooth effect of any shape (a bow, a cyclic error whose pitch no term
//! matches, a drift) makes neighbours alike. The statistic is the lag-one autocorrelation
//! of the residual about each setup's mean (a Durbin-Watson statistic in another form); its
//! null distribution comes from the same residuals shuffled within each setup, so it rests on
//! no noise level and no term of a dictionary.

use crate::campaign::Campaign;
use crate::obs::RowValue;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::collections::BTreeMap;

/// Shuffles of the null distribution per direction.
const SHUFFLES: usize = 200;
/// Fewest neighbour pairs of a direction worth a test.
const MIN_PAIRS: usize = 12;

/// The direction whose neighbours are most alike.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Neighbours {
    pub instrument: String,
    pub direction: String,
    /// Lag-one autocorrelation of the residual along the setups' paths.
    pub autocorrelation: f64,
    /// Its distance from the shuffled residuals' mean in their standard deviations.
    pub z_score: f64,
    /// One-sided p-value (neighbours more alike than shuffled), corrected for the number of
    /// directions tested (Bonferroni).
    pub p_value: f64,
    pub tests: usize,
    pub pairs: usize,
}

/// The neighbour test of the residual `rows` (None: no direction has enough pairs).
pub fn neighbours(campaign: &Campaign, rows: &[RowValue]) -> Option<Neighbours> {
    let mut groups: BTreeMap<(String, String), Vec<&RowValue>> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.sigma > 0.0) {
        groups
            .entry((r.instrument.as_str().to_owned(), r.direction.to_string()))
            .or_default()
            .push(r);
    }
    let mut rng = StdRng::seed_from_u64(0x6e65_6967_6862_6f75);
    let mut best: Option<Neighbours> = None;
    let mut tests = 0;
    for ((instrument, direction), g) in groups {
        let paths = paths(campaign, &g);
        let pairs: usize = paths.iter().map(|p| p.len().saturating_sub(1)).sum();
        if pairs < MIN_PAIRS {
            continue;
        }
        tests += 1;
        let Some((rho, z)) = shuffled_z(&paths, &mut rng) else {
            continue;
        };
        if best.as_ref().is_none_or(|b| z > b.z_score) {
            best = Some(Neighbours {
                instrument,
                direction,
                autocorrelation: rho,
                z_score: z,
                p_value: 0.5 * crate::stats::chi2_upper_tail(z.max(0.0).powi(2), 1.0),
                tests: 0,
                pairs,
            });
        }
    }
    best.map(|mut b| {
        b.tests = tests;
        if b.z_score <= 0.0 {
            b.p_value = 1.0;
        }
        b.p_value = (b.p_value * tests as f64).min(1.0);
        b
    })
}

/// Each setup's weighted residuals in pose order, less the setup's mean.
fn paths(campaign: &Campaign, rows: &[&RowValue]) -> Vec<Vec<f64>> {
    let mut by_setup: BTreeMap<&str, Vec<(usize, f64)>> = BTreeMap::new();
    for r in rows {
        by_setup
            .entry(campaign.poses[r.pose].setup.as_str())
            .or_default()
            .push((r.pose, r.value / r.sigma));
    }
    by_setup
        .into_values()
        .filter(|p| p.len() >= 3)
        .map(|mut p| {
            p.sort_by_key(|e| e.0);
            let mean = p.iter().map(|e| e.1).sum::<f64>() / p.len() as f64;
            p.into_iter().map(|e| e.1 - mean).collect()
        })
        .collect()
}

/// Lag-one autocorrelation over every path.
fn autocorrelation(paths: &[Vec<f64>]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for p in paths {
        num += p.windows(2).map(|w| w[0] * w[1]).sum::<f64>();
        den += p.iter().map(|v| v * v).sum::<f64>();
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// The paths' autocorrelation and its z-score against the paths shuffled within each setup.
fn shuffled_z(paths: &[Vec<f64>], rng: &mut StdRng) -> Option<(f64, f64)> {
    let rho = autocorrelation(paths);
    let mut shuffled = paths.to_vec();
    let mut sum = 0.0;
    let mut sum2 = 0.0;
    for _ in 0..SHUFFLES {
        for p in &mut shuffled {
            p.shuffle(rng);
        }
        let r = autocorrelation(&shuffled);
        sum += r;
        sum2 += r * r;
    }
    let n = SHUFFLES as f64;
    let mean = sum / n;
    let sd = (sum2 / n - mean * mean).max(0.0).sqrt();
    (sd > 0.0).then(|| (rho, (rho - mean) / sd))
}
