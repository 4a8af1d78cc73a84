//! The drift monitor: the estimate's history, its settling times and the drift test run on it.

use super::change::EstimateChange;
use super::drift::{
    candidates_p, creep_fits, expansion_directions, project_out, CreepFit, Drift, DriftTest,
    Whitened, DRIFT_NAME_MARGIN, DRIFT_SETTLE_AFTER_STEP_S, DRIFT_SETTLE_S,
};
use super::estimator::OnlineEstimator;
use super::options::{scale, StepCandidates};
use crate::params::{Params, N_PARAMS};
use nalgebra::SVector;

/// The history of the tracked parameters (a fixed ring of points, allocated once), the
/// reference of the estimator's change and the drift test of it.
#[derive(Clone, Debug)]
pub struct DriftMonitor {
    /// Time of the first point since the start or the last rebase.
    start: Option<f64>,
    /// Time and estimate at the drift test's reference, once settled.
    reference: Option<(f64, Params)>,
    ring: Vec<(f64, f64, Params)>,
    next: usize,
    capacity: usize,
    settle_s: f64,
    candidates: StepCandidates,
}

impl DriftMonitor {
    /// Keeps up to `capacity` points (older ones are overwritten); the reference is taken
    /// [`DRIFT_SETTLE_S`] after the first point.
    pub fn new(capacity: usize) -> DriftMonitor {
        let capacity = capacity.max(2);
        DriftMonitor {
            start: None,
            reference: None,
            ring: Vec::with_capacity(capacity),
            next: 0,
            capacity,
            settle_s: DRIFT_SETTLE_S,
            candidates: StepCandidates::Rods,
        }
    }

    /// Records the estimate of `est` at time `t` with the temperature `temp` (NaN: none):
    /// once settled (the estimator's change then rebased to now), the drift test of its change
    /// since (None before).
    pub fn record(&mut self, t: f64, temp: f64, est: &mut OnlineEstimator) -> Option<DriftTest> {
        let start = *self.start.get_or_insert(t);
        if self.reference.is_none() {
            if t - start < self.settle_s {
                return None;
            }
            est.rebase_change();
            self.reference = Some((t, *est.params()));
        }
        let p = *est.params();
        if self.ring.len() < self.capacity {
            self.ring.push((t, temp, p));
        } else {
            self.ring[self.next] = (t, temp, p);
        }
        self.next = (self.next + 1) % self.capacity;
        Some(self.test(&est.change()))
    }

    /// Restarts after a step was reported: settles again from now, for
    /// [`DRIFT_SETTLE_AFTER_STEP_S`].
    pub fn rebase(&mut self) {
        self.settle_s = DRIFT_SETTLE_AFTER_STEP_S;
        self.start = None;
        self.reference = None;
        self.ring.clear();
        self.next = 0;
    }

    /// The drift test of `change` (the estimator's, [`OnlineEstimator::change`]): its χ² once
    /// the expansion of the rods and the frame is taken out, and the single parameter whose
    /// creep explains the rest best, with its track's correlation with the temperature.
    fn test(&self, change: &EstimateChange) -> DriftTest {
        let w = Whitened::new(change);
        let p0 = self.reference.map_or_else(Params::nominal, |r| r.1);
        let mut basis: Vec<SVector<f64, N_PARAMS>> = Vec::with_capacity(2);
        let mut expansion_ppm = [f64::NAN; 2];
        let raw = expansion_directions(&p0).map(|g| w.cols * g);
        for (k, v) in raw.iter().enumerate() {
            let mut q = *v;
            project_out(&mut q, &basis);
            // an expansion the forces did not see (or the other part's again) fits nothing
            if q.norm() > 1e-6 * v.norm() && q.norm() > 0.0 {
                basis.push(q.normalize());
                expansion_ppm[k] = 0.0;
            }
        }
        fit_expansion(&raw, &w.z, &mut expansion_ppm);
        let mut z = w.z;
        project_out(&mut z, &basis);
        let chi2 = z.norm_squared();
        let dof = w.rank.saturating_sub(basis.len());
        let omnibus_p_value = if dof == 0 {
            1.0
        } else {
            crate::stats::chi2_upper_tail(chi2, dof as f64)
        };
        let fits = creep_fits(&w, &basis, &z);
        let d = scale();
        let p_value = candidates_p(&fits, &self.candidates.states(), dof);
        DriftTest {
            chi2,
            dof,
            omnibus_p_value,
            p_value,
            expansion_ppm,
            explains: std::array::from_fn(|i| fits[i].2),
            rates: std::array::from_fn(|i| fits[i].1 * d[i]),
            best: self.name(&w, &fits, chi2, change),
        }
    }

    /// The candidate whose creep explains the rest of the change best (`fits` from
    /// [`creep_fits`], `chi2` the rest's).
    fn name(
        &self,
        w: &Whitened,
        fits: &[CreepFit],
        chi2: f64,
        change: &EstimateChange,
    ) -> Option<Drift> {
        let mut order: Vec<usize> = self
            .candidates
            .states()
            .into_iter()
            .filter(|&i| i < N_PARAMS && fits[i].2 > 0.0)
            .collect();
        order.sort_by(|&a, &b| fits[b].2.total_cmp(&fits[a].2));
        let &param = order.first()?;
        let (u, rate, gain) = &fits[param];
        let next = order.get(1).copied();
        let margin = next.map_or(f64::INFINITY, |n| gain / fits[n].2.max(f64::MIN_POSITIVE));
        let d = scale()[param];
        // the estimate's track as this parameter's creep (its least-squares fit at each
        // point, in the metric now), for the correlation with the temperature
        let along = w.w.transpose() * u;
        let candidates_alike = std::array::from_fn(|i| {
            (order.contains(&i) && fits[i].2 * DRIFT_NAME_MARGIN >= *gain)
                .then(|| fits[i].1 * scale()[i] * change.input_now)
        });
        Some(Drift {
            param,
            margin,
            candidates_alike,
            rate: rate * d,
            rate_sigma: u.norm().recip() * d,
            input: change.input,
            change: rate * d * change.input_now,
            over_s: change
                .since_s
                .zip(self.latest().map(|l| l.0))
                .map_or(0.0, |(t0, t)| t - t0),
            explained: if chi2 > 0.0 { gain / chi2 } else { 0.0 },
            alike: (0..N_PARAMS)
                .filter(|i| !order.contains(i) && fits[*i].2 * DRIFT_NAME_MARGIN >= *gain)
                .count(),
            temperature_correlation: self.correlation(&along),
        })
    }

    fn latest(&self) -> Option<&(f64, f64, Params)> {
        let last = (self.next + self.capacity - 1) % self.capacity;
        self.ring.get(last).or_else(|| self.ring.last())
    }

    /// Pearson correlation with the temperature of the estimate's track since the reference
    /// projected on `along` (scaled units).
    fn correlation(&self, along: &SVector<f64, N_PARAMS>) -> Option<f64> {
        let (_, p0) = self.reference?;
        let d = scale();
        let pts: Vec<(f64, f64)> = self
            .ring
            .iter()
            .filter(|(_, temp, _)| temp.is_finite())
            .map(|(_, temp, p)| {
                let y = (0..N_PARAMS)
                    .map(|j| along[j] * (p[j] - p0[j]) / d[j])
                    .sum();
                (*temp, y)
            })
            .collect();
        if pts.len() < 8 {
            return None;
        }
        let n = pts.len() as f64;
        let (mx, my) = pts
            .iter()
            .fold((0.0, 0.0), |a, b| (a.0 + b.0 / n, a.1 + b.1 / n));
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for (x, y) in &pts {
            sxy += (x - mx) * (y - my);
            sxx += (x - mx).powi(2);
            syy += (y - my).powi(2);
        }
        (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
    }
}

/// The least-squares expansion rates (ppm per unit of the input) of the parts the forces saw
/// (`ppm` not NaN), from their whitened responses `raw` and the whitened change `z`.
fn fit_expansion(
    raw: &[SVector<f64, N_PARAMS>; 2],
    z: &SVector<f64, N_PARAMS>,
    ppm: &mut [f64; 2],
) {
    let seen: Vec<usize> = (0..2).filter(|&k| ppm[k].is_finite()).collect();
    let n = seen.len();
    if n == 0 {
        return;
    }
    let a = nalgebra::DMatrix::from_fn(N_PARAMS, n, |r, c| raw[seen[c]][r]);
    let b = nalgebra::DVector::from_column_slice(z.as_slice());
    let Some(x) = (a.transpose() * &a)
        .cholesky()
        .map(|c| c.solve(&(a.transpose() * b)))
    else {
        return;
    };
    for (c, &k) in seen.iter().enumerate() {
        ppm[k] = x[c];
    }
}
