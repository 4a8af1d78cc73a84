//! Calibration that never stops (issue 15): the 29 parameters and the stiffness factor
//! tracked from the drive forces of a machine at work, all four drives position-controlled.
//!
//! An extended Kalman filter over the state (p, dk), dk the relative change of the default
//! stiffness, fed by decimated drive samples (q, f1..f4):
//!
//! - predict: the parameters are random walks (lengths and angles drift with temperature and
//!   wear at [`OnlineOptions::length_drift_mm_per_sqrt_h`] ...), the covariance grows with the
//!   time since the last sample;
//! - update: the four force rows of the sample (`obs::force_jacobian`: the elastic model's
//!   forces at the estimate, their Jacobian, the stiffness column f / (1 + dk)), in Joseph
//!   form, static-size matrices, nothing allocated per sample;
//! - step changes: a sample whose normalised innovation exceeds the gate (χ²₄ at 1e-6) is
//!   held back; [`OnlineOptions::step_samples`] in a row are a step (one lone sample is an
//!   outlier, dropped): the single parameter that best explains the held samples' innovations
//!   is named, its variance opened by the step's square, and the held samples are applied.
//!
//! The forces determine some combinations of the parameters (`rpkm analyze observability
//! --method currents`); the start covariance (a calibration's, or the tolerances) holds the
//! rest, whose σ then grows with the drift allowed.

use super::Prior;
use crate::elastic::{sensitivity, ElasticError, Equilibrium, Stiffness, ALL_ACTIVE};
use crate::obs::force_jacobian;
use crate::params::{unit, Params, Unit, N_PARAMS};
use nalgebra::{Matrix4, SMatrix, SVector, Vector3, Vector4};
use std::fmt::Write as _;

/// The state's units inside the filter: the tolerance prior (0.1 mm, 1 mrad) and 10 % of
/// the stiffness.
fn scale() -> SVector<f64, N_STATE> {
    let prior = Prior::default();
    SVector::from_fn(|i, _| if i == STIFFNESS { 0.1 } else { prior.sigma(i) })
}

/// Unknowns: the 29 parameters, then the stiffness change.
pub const N_STATE: usize = N_PARAMS + 1;
/// Index of the stiffness change in the state.
pub const STIFFNESS: usize = N_PARAMS;
/// Gate of the normalised innovation of one sample (4 forces): χ²₄ quantile at 1 − 1e-6.
pub const GATE_CHI2_4: f64 = 33.4;

pub type Covariance = SMatrix<f64, N_STATE, N_STATE>;
type Rows = SMatrix<f64, 4, N_STATE>;

/// Settings of the online estimator.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OnlineOptions {
    /// σ of a drive force reading, N.
    pub force_sigma_n: f64,
    /// Random-walk rate of the lengths, mm per √h (thermal drift of a steel machine: about
    /// 11.5 µm per m and K).
    pub length_drift_mm_per_sqrt_h: f64,
    /// Random-walk rate of the angles, rad per √h.
    pub angle_drift_rad_per_sqrt_h: f64,
    /// Random-walk rate of the stiffness change, per √h.
    pub stiffness_drift_per_sqrt_h: f64,
    /// σ of the stiffness change at the start (0: held at the start value, the default).
    pub stiffness_sigma: f64,
    /// Gated samples in a row that make a step change.
    pub step_samples: usize,
    /// A step is named once its best parameter explains the held innovations this many
    /// times better (χ² reduction) than the next ([`StepChange::margin`]) ...
    pub step_margin: f64,
    /// ... or when this many samples are held, whatever the margin.
    pub step_max_samples: usize,
    /// Which parameters a step change may be: a crash bends a rod, so the rod lengths by
    /// default (the forces cannot tell a rod's length from its joints' positions along it).
    pub step_candidates: StepCandidates,
}

/// The parameters a step change is attributed to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepCandidates {
    /// l1..l5.
    Rods,
    /// Every state (29 parameters and the stiffness).
    All,
}

impl StepCandidates {
    fn states(self) -> Vec<usize> {
        match self {
            StepCandidates::Rods => crate::params::RODS.iter().map(|r| r.l).collect(),
            StepCandidates::All => (0..N_STATE).collect(),
        }
    }
}

impl Default for OnlineOptions {
    fn default() -> Self {
        OnlineOptions {
            force_sigma_n: 5.0,
            length_drift_mm_per_sqrt_h: 0.05,
            angle_drift_rad_per_sqrt_h: 2e-5,
            stiffness_drift_per_sqrt_h: 0.0,
            // held: forces alone cannot tell it from the geometry (rpkm analyze
            // observability --method currents); an offline calibration of forces and
            // followers gives it
            stiffness_sigma: 1e-6,
            step_samples: 10,
            step_margin: 1.5,
            step_max_samples: 60,
            step_candidates: StepCandidates::Rods,
        }
    }
}

/// A step change found in the forces.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct StepChange {
    /// State index of the parameter that explains it best ([`STIFFNESS`] for the stiffness).
    pub param: usize,
    /// Its change, mm or rad (relative for the stiffness), and that estimate's σ.
    pub change: f64,
    pub sigma: f64,
    /// Time of the first held sample, s.
    pub since_s: f64,
    /// How much better it explains the held innovations than the next best parameter
    /// (ratio of their χ² reductions).
    pub margin: f64,
    /// The next best parameter when the margin stayed below
    /// [`OnlineOptions::step_margin`] until [`OnlineOptions::step_max_samples`]: the path
    /// could not tell the two apart (rods 1 and 3 move the forces alike everywhere on the
    /// workspace: their force columns are 0.985 to 0.996 parallel over two minutes of path,
    /// 0.9999 over any ten seconds), and the step is "this or that".
    pub alternative: Option<usize>,
}

/// What one sample did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// Applied, with its normalised innovation.
    Applied { nis: f64 },
    /// Held back (innovation beyond the gate): an outlier or the start of a step.
    Held { nis: f64 },
    /// The held samples were a step: named, and applied.
    Step(StepChange),
}

/// One decimated drive sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceSample {
    pub t: f64,
    pub q: [f64; 4],
    pub f: [f64; 4],
}

/// A held sample, linearised.
#[derive(Clone, Copy, Debug)]
struct Held {
    sample: ForceSample,
    h: Rows,
    y: Vector4<f64>,
}

/// The online estimator (see the module documentation).
#[derive(Clone, Debug)]
pub struct OnlineEstimator {
    p: Params,
    dk: f64,
    /// Covariance of the state in units of [`scale`] (lengths in 0.1 mm, angles in mrad,
    /// the stiffness in 10 %): forces of 1e5 N/mm against 1e8 N/rad would otherwise lose
    /// the update's digits.
    cov: Covariance,
    opts: OnlineOptions,
    last_t: Option<f64>,
    warm: Option<Equilibrium>,
    /// Held samples (capacity `step_max_samples`, allocated once).
    held: Vec<Held>,
    applied: usize,
    outliers: usize,
}

impl OnlineEstimator {
    /// Starts at `p` with covariance `cov` over (p, dk) (a calibration's, see
    /// [`OnlineEstimator::from_sigmas`]).
    pub fn new(p: Params, cov: Covariance, opts: OnlineOptions) -> OnlineEstimator {
        let d = scale();
        OnlineEstimator {
            p,
            dk: 0.0,
            cov: Covariance::from_fn(|i, j| cov[(i, j)] / (d[i] * d[j])),
            opts,
            last_t: None,
            warm: None,
            held: Vec::with_capacity(opts.step_max_samples.max(opts.step_samples).max(1)),
            applied: 0,
            outliers: 0,
        }
    }

    /// Starts at `p`, each parameter with its own σ (a calibration's posterior, or the
    /// tolerance prior where `sigma` is None), the stiffness with the options' σ.
    pub fn from_sigmas(p: Params, sigma: Option<&[f64; N_PARAMS]>, opts: OnlineOptions) -> Self {
        let prior = Prior::default();
        let mut cov = Covariance::zeros();
        for i in 0..N_PARAMS {
            cov[(i, i)] = sigma.map_or(prior.sigma(i), |s| s[i]).powi(2);
        }
        cov[(STIFFNESS, STIFFNESS)] = opts.stiffness_sigma.powi(2);
        OnlineEstimator::new(p, cov, opts)
    }

    pub fn params(&self) -> &Params {
        &self.p
    }
    /// The stiffness change (the machine's stiffness is the default times 1 + this).
    pub fn stiffness_change(&self) -> f64 {
        self.dk
    }
    /// Covariance of the state (mm, rad, relative stiffness).
    pub fn covariance(&self) -> Covariance {
        let d = scale();
        Covariance::from_fn(|i, j| self.cov[(i, j)] * d[i] * d[j])
    }
    /// σ of state `i`.
    pub fn sigma(&self, i: usize) -> f64 {
        self.cov[(i, i)].max(0.0).sqrt() * scale()[i]
    }
    /// How far `p` lies from the estimate in the estimate's own covariance (√ of the
    /// Mahalanobis distance over the 29 parameters): a move along a combination the forces
    /// determine counts by its σ, not by the marginal σ of each parameter, which the
    /// combinations the forces cannot see keep wide.
    pub fn distance(&self, p: &Params) -> f64 {
        let d = scale();
        let pp = self.cov.fixed_view::<N_PARAMS, N_PARAMS>(0, 0).into_owned();
        let dx = SVector::<f64, N_PARAMS>::from_fn(|i, _| (self.p[i] - p[i]) / d[i]);
        pp.cholesky()
            .map_or(f64::INFINITY, |c| dx.dot(&c.solve(&dx)).max(0.0).sqrt())
    }

    /// Samples applied and outliers dropped so far.
    pub fn counts(&self) -> (usize, usize) {
        (self.applied, self.outliers)
    }

    fn state(&self, i: usize) -> f64 {
        if i == STIFFNESS {
            self.dk
        } else {
            self.p[i]
        }
    }

    fn set_state(&mut self, i: usize, v: f64) {
        if i == STIFFNESS {
            self.dk = v;
        } else {
            self.p[i] = v;
        }
    }

    fn stiffness(&self) -> Stiffness {
        Stiffness::default().scaled(1.0 + self.dk)
    }

    /// The covariance grows by the drift allowed over `dt` seconds.
    fn predict(&mut self, t: f64) {
        let dt_h = self.last_t.map_or(0.0, |t0| (t - t0).max(0.0)) / 3600.0;
        self.last_t = Some(t);
        let o = &self.opts;
        for i in 0..N_PARAMS {
            let rate = match unit(i) {
                Unit::Mm => o.length_drift_mm_per_sqrt_h,
                Unit::Rad => o.angle_drift_rad_per_sqrt_h,
            };
            self.cov[(i, i)] += rate * rate * dt_h / scale()[i].powi(2);
        }
        self.cov[(STIFFNESS, STIFFNESS)] +=
            o.stiffness_drift_per_sqrt_h.powi(2) * dt_h / scale()[STIFFNESS].powi(2);
    }

    /// The sample's force rows at the estimate: Jacobian over the state and innovation.
    fn linearise(&mut self, s: &ForceSample) -> Result<Held, ElasticError> {
        let k = self.stiffness();
        let (eq, dp) = match force_jacobian(&self.p, &k, s.q, self.warm.as_ref()) {
            Ok(v) => v,
            // a warm start from a far pose (a jump in the stream): solve cold
            Err(_) if self.warm.is_some() => force_jacobian(&self.p, &k, s.q, None)?,
            Err(e) => return Err(e),
        };
        self.warm = Some(eq);
        let mut h = Rows::zeros();
        let mut y = Vector4::zeros();
        let d = scale();
        for a in 0..4 {
            for j in 0..N_PARAMS {
                h[(a, j)] = dp[a][j] * d[j];
            }
            h[(a, STIFFNESS)] = eq.drive_force[a] / (1.0 + self.dk) * d[STIFFNESS];
            y[a] = s.f[a] - eq.drive_force[a];
        }
        Ok(Held { sample: *s, h, y })
    }

    fn innovation_cov(&self, h: &Rows) -> Matrix4<f64> {
        let r = self.opts.force_sigma_n.powi(2);
        h * self.cov * h.transpose() + Matrix4::identity() * r
    }

    /// Update with one linearised sample in information form (the information gained is
    /// added, never subtracted: a force row carries 10⁸ times the information of the prior
    /// in its direction, where the covariance form loses its positive definiteness); its
    /// normalised innovation.
    fn apply(&mut self, held: &Held) -> f64 {
        let nis = self.nis(held);
        let r = self.opts.force_sigma_n.powi(2);
        let Some(prior) = self.cov.cholesky() else {
            return f64::NAN;
        };
        let info = prior.inverse() + held.h.transpose() * held.h / r;
        let info = (info + info.transpose()) * 0.5;
        let Some(post) = info.cholesky() else {
            return f64::NAN;
        };
        let dx: SVector<f64, N_STATE> = post.solve(&(held.h.transpose() * held.y / r));
        let d = scale();
        for i in 0..N_PARAMS {
            self.p[i] += dx[i] * d[i];
        }
        self.dk += dx[STIFFNESS] * d[STIFFNESS];
        let cov = post.inverse();
        self.cov = (cov + cov.transpose()) * 0.5;
        self.applied += 1;
        nis
    }

    /// Normalised innovation of a linearised sample.
    fn nis(&self, held: &Held) -> f64 {
        let s = self.innovation_cov(&held.h);
        let s = (s + s.transpose()) * 0.5;
        s.cholesky()
            .map_or(f64::INFINITY, |c| held.y.dot(&c.solve(&held.y)))
    }

    /// One decimated sample of the drives: predict, gate, update (or hold, or find a step).
    pub fn update(&mut self, sample: &ForceSample) -> Result<Outcome, ElasticError> {
        self.predict(sample.t);
        let held = self.linearise(sample)?;
        let s = self.innovation_cov(&held.h);
        let nis = s.try_inverse().map_or(f64::INFINITY, |si| {
            (held.y.transpose() * si * held.y)[(0, 0)]
        });
        if nis <= GATE_CHI2_4 {
            if self.held.len() >= self.opts.step_samples.max(1) {
                // a step the path has moved away from: named with what was held
                let step = self.step_found();
                let again = self.linearise(sample)?;
                self.apply(&again);
                return Ok(Outcome::Step(step));
            }
            // fewer gated samples than a step: outliers
            self.outliers += self.held.len();
            self.held.clear();
            return Ok(Outcome::Applied {
                nis: self.apply(&held),
            });
        }
        self.held.push(held);
        if self.held.len() < self.opts.step_samples.max(1) {
            return Ok(Outcome::Held { nis });
        }
        let margin = self.attribute_step().margin;
        if margin < self.opts.step_margin && self.held.len() < self.opts.step_max_samples {
            return Ok(Outcome::Held { nis });
        }
        Ok(Outcome::Step(self.step_found()))
    }

    /// Names the step of the held samples, applies it, and the held samples after it.
    fn step_found(&mut self) -> StepChange {
        let mut step = self.attribute_step();
        if step.margin >= self.opts.step_margin {
            step.alternative = None;
        }
        // the step itself, then the held samples through the filter with the parameter's
        // variance opened by a fifth of it (a one-parameter fit of a few poses is close,
        // not exact): spreading the whole step over every parameter the forces see alike
        // would move the ones they cannot tell apart
        self.set_state(step.param, self.state(step.param) + step.change);
        let c = 0.2 * step.change;
        self.cov[(step.param, step.param)] +=
            (c * c + step.sigma * step.sigma) / scale()[step.param].powi(2);
        // the held samples are spent on the step's size: through the filter again they
        // would pull the combinations the forces cannot tell from the step (a start
        // covariance without its correlations leaves them free) and move the TCP
        self.held.clear();
        step
    }

    /// The single state that best explains the held innovations (least squares of each
    /// alone, weighted by the force noise): its change and margin.
    fn attribute_step(&self) -> StepChange {
        let mut g = [0.0; N_STATE];
        let mut c = [0.0; N_STATE];
        for h in &self.held {
            let w = self.opts.force_sigma_n.powi(-2);
            for i in 0..N_STATE {
                let col = h.h.column(i);
                g[i] += w * col.dot(&h.y);
                c[i] += w * col.dot(&col);
            }
        }
        let gain = |i: usize| if c[i] > 0.0 { g[i] * g[i] / c[i] } else { 0.0 };
        let mut order = self.opts.step_candidates.states();
        order.sort_by(|&a, &b| gain(b).total_cmp(&gain(a)));
        let best = order[0];
        let next = order.get(1).copied().unwrap_or(best);
        let d = scale()[best];
        StepChange {
            param: best,
            change: g[best] / c[best] * d,
            sigma: c[best].powf(-0.5) * d,
            since_s: self.held[0].sample.t,
            margin: gain(best) / gain(next).max(f64::MIN_POSITIVE),
            // the runner-up, kept by the caller only while the margin is not clear
            alternative: (next != best).then_some(next),
        }
    }

    /// The TCP (x, y mm, ψ rad) the estimate gives for drive positions `q`, and its σ
    /// propagated from the estimate's covariance (the geometry's part; the stiffness moves
    /// no pose).
    pub fn tcp(&self, q: [f64; 4]) -> Result<(Vector3<f64>, Vector3<f64>), ElasticError> {
        let k = self.stiffness();
        let eq = crate::elastic::fegm(&self.p, &k, q, ALL_ACTIVE)?;
        let sens = sensitivity(&self.p, &k, q, ALL_ACTIVE, &eq)?;
        let full = self.covariance();
        let pp = full.fixed_view::<N_PARAMS, N_PARAMS>(0, 0);
        let cov = sens.dpose_dp * pp * sens.dpose_dp.transpose();
        Ok((
            Vector3::new(eq.x, eq.y, eq.psi),
            Vector3::from_fn(|i, _| cov[(i, i)].max(0.0).sqrt()),
        ))
    }
}

/// A parameter that moved beyond the threshold since the tracking began.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Drift {
    /// Parameter index.
    pub param: usize,
    /// Change since the reference, mm or rad, and over how long, s.
    pub change: f64,
    pub over_s: f64,
    /// Correlation of its track with the temperature (None without a temperature, or too
    /// few points).
    pub temperature_correlation: Option<f64>,
}

impl Drift {
    /// "l3 +12 µm in 40 min, follows temp_machine" (the temperature named `temp_name`).
    pub fn describe(&self, temp_name: &str) -> String {
        let (v, unit) = match unit(self.param) {
            Unit::Mm => (self.change * 1e3, "µm"),
            Unit::Rad => (self.change * 1e6, "µrad"),
        };
        let mut s = format!(
            "{} {v:+.0} {unit} in {:.0} min",
            crate::params::NAMES[self.param],
            self.over_s / 60.0
        );
        if let Some(r) = self.temperature_correlation.filter(|r| r.abs() >= FOLLOWS) {
            let _ = write!(s, ", follows {temp_name} (r = {r:.2})");
        }
        s
    }
}

/// Correlation with the temperature from which a drift "follows" it.
pub const FOLLOWS: f64 = 0.9;

/// The history of the tracked parameters (a fixed ring of points, allocated once) and what
/// moved in it.
#[derive(Clone, Debug)]
pub struct DriftMonitor {
    reference: Option<(f64, Params)>,
    ring: Vec<(f64, f64, Params)>,
    next: usize,
    capacity: usize,
}

impl DriftMonitor {
    /// Keeps up to `capacity` points (older ones are overwritten).
    pub fn new(capacity: usize) -> DriftMonitor {
        let capacity = capacity.max(2);
        DriftMonitor {
            reference: None,
            ring: Vec::with_capacity(capacity),
            next: 0,
            capacity,
        }
    }

    /// Records the estimate `p` at time `t` with the temperature `temp` (NaN: none). The
    /// first point is the reference.
    pub fn record(&mut self, t: f64, temp: f64, p: &Params) {
        if self.reference.is_none() {
            self.reference = Some((t, *p));
        }
        if self.ring.len() < self.capacity {
            self.ring.push((t, temp, *p));
        } else {
            self.ring[self.next] = (t, temp, *p);
        }
        self.next = (self.next + 1) % self.capacity;
    }

    /// Restarts from the estimate now (after a step was reported, or drifts acknowledged).
    pub fn rebase(&mut self) {
        self.reference = None;
        self.ring.clear();
        self.next = 0;
    }

    /// The parameters whose change from the reference exceeds both `threshold` (mm; rad
    /// thresholds are `threshold` / 1000 mm) and 3σ of the estimate (`sigma`), largest first.
    pub fn drifts(&self, threshold_mm: f64, sigma: &[f64; N_PARAMS]) -> Vec<Drift> {
        let (Some((t0, p0)), Some(&(t, _, p))) = (self.reference, self.latest()) else {
            return Vec::new();
        };
        let mut out: Vec<Drift> = (0..N_PARAMS)
            .filter_map(|i| {
                let change = p[i] - p0[i];
                let threshold = match unit(i) {
                    Unit::Mm => threshold_mm,
                    Unit::Rad => threshold_mm / 1000.0,
                };
                (change.abs() > threshold && change.abs() > 3.0 * sigma[i]).then(|| Drift {
                    param: i,
                    change,
                    over_s: t - t0,
                    temperature_correlation: self.correlation(i),
                })
            })
            .collect();
        out.sort_by(|a, b| {
            (b.change / sigma[b.param])
                .abs()
                .total_cmp(&(a.change / sigma[a.param]).abs())
        });
        out
    }

    fn latest(&self) -> Option<&(f64, f64, Params)> {
        let last = (self.next + self.capacity - 1) % self.capacity;
        self.ring.get(last).or_else(|| self.ring.last())
    }

    /// Pearson correlation of parameter `i`'s track with the temperature.
    fn correlation(&self, i: usize) -> Option<f64> {
        let pts: Vec<(f64, f64)> = self
            .ring
            .iter()
            .filter(|(_, temp, _)| temp.is_finite())
            .map(|(_, temp, p)| (*temp, p[i]))
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
