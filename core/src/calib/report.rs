//! What a calibration reports about its rows: outliers, RMS per instrument and direction,
//! and the held-out figures (gain, RMS).

use super::rows::Key;
use super::types::{DirectionRms, Outlier};
use crate::campaign::{Campaign, Instrument};
use crate::obs::{Direction, RowValue};
use std::collections::BTreeMap;

/// Rows further than `k` standard deviations from the mean of their instrument and direction.
pub(super) fn find_outliers(rows: &[RowValue], campaign: &Campaign, k: f64) -> Vec<(Key, Outlier)> {
    let mut groups: BTreeMap<(&str, Direction), Vec<&RowValue>> = BTreeMap::new();
    for r in rows {
        groups
            .entry((r.instrument.as_str(), r.direction))
            .or_default()
            .push(r);
    }
    let mut out = Vec::new();
    for ((inst, dir), g) in groups {
        if g.len() < 8 {
            continue; // too few rows for a trustworthy standard deviation
        }
        let n = g.len() as f64;
        let mean = g.iter().map(|r| r.value).sum::<f64>() / n;
        let sd = (g.iter().map(|r| (r.value - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        for r in g {
            let dev = (r.value - mean).abs() / sd;
            if sd > 0.0 && dev > k {
                out.push((
                    (r.pose, r.direction),
                    Outlier {
                        line: campaign.poses[r.pose].line,
                        instrument: inst.to_string(),
                        direction: dir.to_string(),
                        residual: r.value,
                        deviations: dev,
                    },
                ));
            }
        }
    }
    out
}

/// RMS per instrument and direction of the same rows at two parameter sets, and their costs,
/// summed as the rows come (piece by piece: a large campaign's rows are not kept twice).
#[derive(Default)]
pub(super) struct RmsTable {
    acc: BTreeMap<(Instrument, Direction), (usize, f64, f64)>,
    pub cost_before: f64,
    pub cost_after: f64,
    /// Rows of the "after" set.
    pub rows: usize,
}

impl RmsTable {
    pub fn before(&mut self, rows: impl IntoIterator<Item = RowValue>) {
        for r in rows {
            let e = self.acc.entry((r.instrument, r.direction)).or_default();
            e.0 += 1;
            e.1 += r.value * r.value;
            self.cost_before += 0.5 * (r.value / r.sigma).powi(2);
        }
    }

    pub fn after(&mut self, rows: impl IntoIterator<Item = RowValue>) {
        for r in rows {
            self.acc.entry((r.instrument, r.direction)).or_default().2 += r.value * r.value;
            self.cost_after += 0.5 * (r.value / r.sigma).powi(2);
            self.rows += 1;
        }
    }

    /// Adds another table's sums (tables merged in a fixed order give the same sums on any
    /// number of threads).
    pub fn merge(&mut self, other: RmsTable) {
        for (key, (n, b, a)) in other.acc {
            let e = self.acc.entry(key).or_default();
            e.0 += n;
            e.1 += b;
            e.2 += a;
        }
        self.cost_before += other.cost_before;
        self.cost_after += other.cost_after;
        self.rows += other.rows;
    }

    pub fn finish(&self) -> Vec<DirectionRms> {
        self.acc
            .iter()
            .map(|(&(inst, dir), &(n, b, a))| DirectionRms {
                instrument: inst.as_str().to_string(),
                direction: dir.to_string(),
                rows: n,
                rms_before: (b / n.max(1) as f64).sqrt(),
                rms_after: (a / n.max(1) as f64).sqrt(),
                is_angle: dir.is_angle(),
                is_force: dir.is_force(),
            })
            .collect()
    }
}

/// Calibration gain on held-out measurement errors (eq. 3.33-3.34): the mean over values of
/// (|ΔW_nc| − |ΔW_cal|) / |ΔW_nc|.
pub fn gain(before: &[f64], after: &[f64]) -> f64 {
    let terms: Vec<f64> = before
        .iter()
        .zip(after)
        .filter(|(b, _)| b.abs() > 0.0)
        .map(|(b, a)| (b.abs() - a.abs()) / b.abs())
        .collect();
    if terms.is_empty() {
        0.0
    } else {
        terms.iter().sum::<f64>() / terms.len() as f64
    }
}

/// RMS of a set of values.
pub fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}
