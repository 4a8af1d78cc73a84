//! The estimator's state and results: construction from a calibration, the random-walk
//! prediction, the readings of the estimate.

use super::change::{ChangeTrack, EstimateChange};
use super::force_noise::ForceNoise;
use super::options::{scale, Covariance, OnlineOptions, Rows, STIFFNESS};
use crate::calib::tie::{SeparatingMotion, TieEvidence};
use crate::calib::Prior;
use crate::elastic::{sensitivity, ElasticError, Equilibrium, Stiffness, ALL_ACTIVE};
use crate::params::{unit, Params, Unit, N_PARAMS};
use nalgebra::{Matrix4, SMatrix, SVector, Vector3, Vector4};

/// A step change found in the forces.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DetectedStep {
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
    /// With an alternative, the motion that tells the two apart: poses of the workspace
    /// grid (all four drives position-controlled, as the tracker reads them) and the
    /// evidence they would give ([`OnlineEstimator::tie_motion`], issue 28); None without
    /// an alternative or where no pose is reachable.
    pub separating: Option<SeparatingMotion>,
}

/// What one sample did.
#[derive(Clone, Debug, PartialEq)]
pub enum UpdateOutcome {
    /// Applied, with its normalised innovation.
    Applied { nis: f64 },
    /// Held back (innovation beyond the gate): an outlier or the start of a step.
    Held { nis: f64 },
    /// The held samples were a step: named, and applied.
    Step(DetectedStep),
    /// The sample (applied, or held) settled a step that was "this or that".
    Resolved(TieResolved),
}

/// A step still "this or that" ([`OnlineEstimator::tie`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TieSoFar {
    /// The parameter the step was named by, and its runner-up.
    pub named: usize,
    pub runner_up: usize,
    /// The evidence since the step (positive: for the named).
    pub evidence: TieEvidence,
}

/// A step told apart from its runner-up by the samples since.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TieResolved {
    /// The parameter that stands, and its change at the step (mm, rad or relative).
    pub param: usize,
    pub change: f64,
    /// The one ruled out.
    pub ruled_out: usize,
    /// When the step began, s.
    pub since_s: f64,
    /// Whether the one that stands was the runner-up: the estimate now carries its change
    /// instead of the named one's.
    pub swapped: bool,
    /// The evidence (for the named when positive).
    pub evidence: TieEvidence,
    /// The TCP (x, y mm) at the sample that said most.
    pub at: Option<(f64, f64)>,
}

/// One decimated drive sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceSample {
    pub t: f64,
    pub q: [f64; 4],
    pub f: [f64; 4],
}

/// A held sample, linearised, with its forces' noise.
#[derive(Clone, Copy, Debug)]
pub(super) struct Held {
    pub(super) sample: ForceSample,
    pub(super) h: Rows,
    pub(super) y: Vector4<f64>,
    /// The forces' covariance at the sample's pose (N², [`DriveNoise`]) and its inverse.
    pub(super) r: Matrix4<f64>,
    pub(super) info: Matrix4<f64>,
}

/// The online estimator (see the module documentation).
#[derive(Clone, Debug)]
pub struct OnlineEstimator {
    pub(super) p: Params,
    pub(super) dk: f64,
    /// Covariance of the state in units of [`scale`] (lengths in 0.1 mm, angles in mrad,
    /// the stiffness in 10 %): forces of 1e5 N/mm against 1e8 N/rad would otherwise lose
    /// the update's digits.
    pub(super) cov: Covariance,
    pub(super) opts: OnlineOptions,
    pub(super) last_t: Option<f64>,
    pub(super) warm: Option<Equilibrium>,
    /// Held samples (capacity `step_max_samples`, allocated once).
    pub(super) held: Vec<Held>,
    pub(super) applied: usize,
    pub(super) outliers: usize,
    /// The estimate's change since a reference, for the drift test.
    pub(super) change: ChangeTrack,
    /// The force noise the filter actually sees, from its innovations (kept across a
    /// rebase: the drives' noise does not change with the reference; None before the first
    /// applied sample, which starts it from the stated σ).
    pub(super) noise_seen: Option<ForceNoise>,
    /// The machine temperature last given, °C (NaN: none).
    pub(super) temp_c: f64,
    /// A step named with its runner-up, until the evidence tells them apart.
    pub(super) tie: Option<Box<OpenTie>>,
}

/// A step that is "this or that": the estimate with the runner-up's change instead of the
/// named one's, and the evidence so far (see [`crate::calib::tie`]).
#[derive(Clone, Debug)]
pub(super) struct OpenTie {
    pub(super) alt: OnlineEstimator,
    /// The step's first held sample, s.
    pub(super) since_s: f64,
    /// The parameters and their changes: the named one's, and the runner-up's fitted to
    /// the same held samples.
    pub(super) named: (usize, f64),
    pub(super) runner_up: (usize, f64),
    pub(super) evidence: TieEvidence,
    /// Whether `alt` holds the named estimate (the runner-up stood and took its place).
    pub(super) swapped: bool,
}

impl OnlineEstimator {
    /// Starts at `p` with covariance `cov` over (p, dk) (a calibration's, see
    /// [`OnlineEstimator::from_sigmas`]).
    pub fn new(p: Params, cov: Covariance, opts: OnlineOptions) -> OnlineEstimator {
        let d = scale();
        let cov = Covariance::from_fn(|i, j| cov[(i, j)] / (d[i] * d[j]));
        OnlineEstimator {
            p,
            dk: 0.0,
            cov,
            change: ChangeTrack::at(p, &cov, None),
            noise_seen: None,
            temp_c: f64::NAN,
            opts,
            last_t: None,
            warm: None,
            held: Vec::with_capacity(opts.step_max_samples.max(opts.step_samples).max(1)),
            applied: 0,
            outliers: 0,
            tie: None,
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

    /// Starts at a calibration's parameters with its full posterior covariance (see
    /// [`OnlineEstimator::from_covariance`]).
    pub fn from_calibration(cal: &crate::calib::Calibration, opts: OnlineOptions) -> Self {
        OnlineEstimator::from_covariance(cal.params, &cal.covariance, opts)
    }

    /// Starts at `p` with the covariance `cov` of a calibration (mm, rad), with the
    /// correlations the campaign left: the forces then move only what the campaign had not
    /// pinned (from the σ alone they would move combinations the campaign had pinned, and
    /// the TCP with them). A parameter with zero variance, which the calibration did not
    /// identify, takes the tolerance prior's σ; the stiffness the options' σ.
    pub fn from_covariance(
        p: Params,
        cov: &SMatrix<f64, N_PARAMS, N_PARAMS>,
        opts: OnlineOptions,
    ) -> Self {
        let prior = Prior::default();
        let mut full = Covariance::zeros();
        full.fixed_view_mut::<N_PARAMS, N_PARAMS>(0, 0)
            .copy_from(cov);
        for i in 0..N_PARAMS {
            if cov[(i, i)] <= 0.0 {
                full[(i, i)] = prior.sigma(i).powi(2);
            }
        }
        full[(STIFFNESS, STIFFNESS)] = opts.stiffness_sigma.powi(2);
        OnlineEstimator::new(p, full, opts)
    }

    pub fn params(&self) -> &Params {
        &self.p
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

    /// A step still "this or that": the two, and the evidence so far (None without one).
    pub fn tie(&self) -> Option<TieSoFar> {
        self.tie.as_ref().map(|t| TieSoFar {
            named: t.named.0,
            runner_up: t.runner_up.0,
            evidence: t.evidence,
        })
    }

    /// Samples applied and outliers dropped so far.
    pub fn counts(&self) -> (usize, usize) {
        (self.applied, self.outliers)
    }

    /// The parameters' change since the reference (the start, the last step, or
    /// [`OnlineEstimator::rebase_change`]), its covariance were nothing to have moved (the
    /// start error the forces go on correcting and the force noise, through the gains the
    /// filter used; its random walk's growth not included: that is what a drift would be),
    /// and the estimate's response to a creep of each parameter (see [`ChangeTrack`]).
    pub fn change(&self) -> EstimateChange {
        let d = scale();
        let c = &self.change;
        let cov = c.covariance();
        EstimateChange {
            since_s: c.t,
            dp: SVector::from_fn(|i, _| self.p[i] - c.p[i]),
            cov: SMatrix::from_fn(|i, j| cov[(i, j)] * d[i] * d[j]),
            response: SMatrix::from_fn(|j, i| c.response[(j, i)] * d[j] / d[i]),
            input: c.input,
            input_now: c.s,
        }
    }

    /// Takes the estimate now as the reference of [`OnlineEstimator::change`].
    pub fn rebase_change(&mut self) {
        self.change = ChangeTrack::at(self.p, &self.cov, self.last_t);
    }

    /// The machine temperature now, °C (NaN: none), for the drift test's input (see
    /// [`OnlineEstimator::change`]); the filter itself knows no temperature.
    pub fn set_temperature(&mut self, temp_c: f64) {
        self.temp_c = temp_c;
    }

    pub(super) fn state(&self, i: usize) -> f64 {
        if i == STIFFNESS {
            self.dk
        } else {
            self.p[i]
        }
    }

    pub(super) fn set_state(&mut self, i: usize, v: f64) {
        if i == STIFFNESS {
            self.dk = v;
        } else {
            self.p[i] = v;
        }
    }

    pub(super) fn stiffness(&self) -> Stiffness {
        Stiffness::default().scaled(1.0 + self.dk)
    }

    /// The covariance grows by the drift allowed over `dt` seconds.
    pub(super) fn predict(&mut self, t: f64) {
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
}

impl OnlineEstimator {
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
