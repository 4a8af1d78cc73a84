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
//!   forces at the estimate, their Jacobian, the stiffness column f / (1 + dk)) weighted by
//!   the forces' covariance with the encoders' share, the calibration's noise model
//!   ([`DriveNoise`]: an encoder's 0.2 µm is 10-20 N of force), in information form,
//!   static-size matrices, nothing allocated per sample;
//! - step changes: a sample whose normalised innovation exceeds the gate (χ²₄ at 1e-6) is
//!   held back; [`OnlineOptions::step_samples`] in a row are a step (one lone sample is an
//!   outlier, dropped): the single parameter that best explains the held samples' innovations
//!   is named, its variance opened by the step's square, and the held samples are applied;
//! - ties: a step the path moved alike for two parameters ("l3 or l1") keeps a second
//!   estimate with the runner-up's change until the two estimates' predictions of the
//!   samples since tell them apart ([`super::tie`]); [`OnlineEstimator::tie_motion`] plans
//!   the poses that would.
//!
//! The forces determine some combinations of the parameters (`rpkm analyze observability
//! --method currents`); the start covariance (a calibration's, or the tolerances) holds the
//! rest, whose σ then grows with the drift allowed.
//!
//! Drift: the random walk that lets the estimate follow a drift widens its σ by as much, so
//! [`DriftMonitor`] weighs the estimate's change since a reference in the covariance that
//! change would have had were nothing to have moved ([`OnlineEstimator::change`]), the
//! expansion of rods and frame fitted out, and tests whether a candidate's creep (a rod's,
//! by default) explains it beyond noise: 1 dof per candidate, not the χ² of the whole change,
//! which under noise alone grows without bound over hours (see [`DriftTest`]).

use super::tie::{plan_motion, Candidate, Prediction, SeparatingMotion, TieEvidence, Verdict};
use super::types::Prior;
use crate::elastic::{sensitivity, ElasticError, Equilibrium, Stiffness, ALL_ACTIVE};
use crate::noise::{DriveNoise, NoiseModel};
use crate::obs::{force_jacobian, force_position_gains};
use crate::params::{unit, Params, Unit, N_PARAMS};
use nalgebra::{Matrix4, SMatrix, SVector, Vector3, Vector4};

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
    /// σ of a drive's encoder, mm: the drives hold their commands, so an encoder's error
    /// moves the forces by the rods' stiffness ([`DriveNoise`]; the calibration's
    /// `drive_position` group).
    pub encoder_sigma_mm: f64,
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
    /// A step named with its runner-up is told apart once the two estimates' predictions of
    /// the samples since differ by this much evidence (χ², −2 log-likelihood ratio) either
    /// way ([`TieEvidence`]).
    pub tie_evidence_chi2: f64,
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

impl OnlineOptions {
    /// The drive forces' noise the filter weighs a sample by.
    pub fn drives(&self) -> DriveNoise {
        DriveNoise {
            force_n: self.force_sigma_n,
            encoder_mm: self.encoder_sigma_mm,
        }
    }
}

impl Default for OnlineOptions {
    fn default() -> Self {
        OnlineOptions {
            force_sigma_n: 5.0,
            // the calibration's stated level
            encoder_sigma_mm: NoiseModel::default().drive_position_mm,
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
            tie_evidence_chi2: TIE_EVIDENCE_CHI2,
            step_candidates: StepCandidates::Rods,
        }
    }
}

/// A step change found in the forces.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
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
    /// With an alternative, the motion that tells the two apart: poses of the workspace
    /// grid (all four drives position-controlled, as the tracker reads them) and the
    /// evidence they would give ([`OnlineEstimator::tie_motion`], issue 28); None without
    /// an alternative or where no pose is reachable.
    pub separating: Option<SeparatingMotion>,
}

/// What one sample did.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Applied, with its normalised innovation.
    Applied { nis: f64 },
    /// Held back (innovation beyond the gate): an outlier or the start of a step.
    Held { nis: f64 },
    /// The held samples were a step: named, and applied.
    Step(StepChange),
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
struct Held {
    sample: ForceSample,
    h: Rows,
    y: Vector4<f64>,
    /// The forces' covariance at the sample's pose (N², [`DriveNoise`]) and its inverse.
    r: Matrix4<f64>,
    info: Matrix4<f64>,
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
    /// The estimate's change since a reference, for the drift test.
    change: ChangeTrack,
    /// The force noise the filter actually sees, from its innovations (kept across a
    /// rebase: the drives' noise does not change with the reference; None before the first
    /// applied sample, which starts it from the stated σ).
    noise_seen: Option<ForceNoise>,
    /// The machine temperature last given, °C (NaN: none).
    temp_c: f64,
    /// A step named with its runner-up, until the evidence tells them apart.
    tie: Option<Box<OpenTie>>,
}

/// A step that is "this or that": the estimate with the runner-up's change instead of the
/// named one's, and the evidence so far (see [`super::tie`]).
#[derive(Clone, Debug)]
struct OpenTie {
    alt: OnlineEstimator,
    /// The step's first held sample, s.
    since_s: f64,
    /// The parameters and their changes: the named one's, and the runner-up's fitted to
    /// the same held samples.
    named: (usize, f64),
    runner_up: (usize, f64),
    evidence: TieEvidence,
    /// Whether `alt` holds the named estimate (the runner-up stood and took its place).
    swapped: bool,
}

/// A prediction that missed: the estimate has no innovation covariance for the sample.
const MISSED: Prediction = Prediction {
    nis: f64::INFINITY,
    ln_det: 0.0,
};

/// Evidence that tells a tie apart: a likelihood ratio of 10⁶ (2 ln 10⁶), the false-alarm
/// level of the gate.
pub const TIE_EVIDENCE_CHI2: f64 = 27.63;

/// Most poses of a motion that settles a tie (a minute of the cell's time at a few
/// seconds a pose).
pub const TIE_MOTION_POSES: usize = 12;

/// What the estimate's change since a reference would be were nothing to have moved: the
/// estimation error evolves as e ← A e + K v (A = I − K H) under noise v alone, so the change
/// e_t − e_r = (Φ − I) e_r + Σ Φ K v, Φ the product of the A since the reference. Its
/// covariance (Φ − I) P_r (Φ − I)ᵀ + M, M ← A M Aᵀ + K R Kᵀ with R the force noise the
/// innovations show ([`ForceNoise`], not the stated σ), stays bounded where the random
/// walk's own covariance grows with time: the random walk lets the estimate follow a drift,
/// and the test still measures the drift against what noise alone would have moved it (the
/// filter's own innovations would not: they are tested against the random walk, which
/// allows any drift this slow). Scaled units, as the filter.
///
/// Beside it, what the filter makes of a parameter that creeps along the input s (the
/// temperature's change since the reference, or the hours where there is no temperature):
/// the truth x_r + e_i s moves the estimate by R e_i, R ← A R + K H s. The forces see a
/// parameter's change only through the combinations they determine, so a creep is compared
/// with the estimate's change through the filter's own response, not as the unit vector.
#[derive(Clone, Debug)]
struct ChangeTrack {
    p: Params,
    cov: Covariance,
    phi: Covariance,
    noise: Covariance,
    response: SMatrix<f64, N_STATE, N_PARAMS>,
    input: DriftInput,
    /// The input now (K or h since the reference).
    s: f64,
    t: Option<f64>,
}

/// The covariance of the force noise as the innovations show it (N²): the filter's stated
/// noise (`force_sigma_n` and `encoder_sigma_mm` through the loop's stiffness,
/// [`DriveNoise`]) is a statement, not the machine's levels (on the twin 3 N of currents
/// where 5 N is stated; an encoder's few tenths of a µm are several N on the four drives'
/// preload at once, one direction of the four forces: 7 N rms a drive at the truth). The change
/// since the reference is K v summed through the filter's gains, so its covariance is
/// K R Kᵀ with the noise v really has, whatever the filter assumed when it chose K (the
/// Joseph form of a suboptimal gain).
///
/// Estimated from the differences of successive innovations, ½ mean Δy Δyᵀ: the noise is
/// independent from sample to sample, so a difference carries it twice, while the
/// innovation's slow part (the filter's lag behind a drift, its prediction error) cancels.
/// The innovations themselves (mean y yᵀ) take that lag for noise: under a creep of l3 they
/// widened M until the drift test lost it for a minute at a time. Their normalised mean
/// (χ² per dof) says nothing of R here: it is 0.18 on the twin, the random walk's H P Hᵀ
/// (10⁴ N² a sample at 0.15 mm/√h) dwarfing R in every direction the forces see.
#[derive(Clone, Copy, Debug)]
struct ForceNoise {
    /// ½ Σ Δy Δyᵀ, the stated R as [`STATED_NOISE_SAMPLES`] samples included.
    sum: Matrix4<f64>,
    n: f64,
    /// The last applied sample's innovation.
    last: Option<Vector4<f64>>,
}

/// The stated force σ counts as this many samples in [`ForceNoise`]'s mean: it holds the
/// first samples (a 4 × 4 covariance from fewer than its 10 entries would be singular) and
/// weighs nothing after the first minute (600 samples at 10 Hz).
const STATED_NOISE_SAMPLES: f64 = 10.0;

impl ForceNoise {
    fn stated(r: &Matrix4<f64>) -> ForceNoise {
        ForceNoise {
            sum: r * STATED_NOISE_SAMPLES,
            n: STATED_NOISE_SAMPLES,
            last: None,
        }
    }

    /// Adds the innovation `y` of an applied sample (its difference from the last one).
    fn add(&mut self, y: &Vector4<f64>) {
        if let Some(last) = self.last.replace(*y) {
            let d = y - last;
            self.sum += d * d.transpose() * 0.5;
            self.n += 1.0;
        }
    }

    fn covariance(&self) -> Matrix4<f64> {
        self.sum / self.n
    }
}

/// What a creep is assumed to follow.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DriftInput {
    /// Not yet known (no sample since the reference).
    Unknown,
    /// The temperature (°C at the reference): changes per K.
    Temperature(f64),
    /// Time, where no temperature is given: changes per hour.
    Time,
}

impl ChangeTrack {
    fn at(p: Params, cov: &Covariance, t: Option<f64>) -> ChangeTrack {
        ChangeTrack {
            p,
            cov: *cov,
            phi: Covariance::identity(),
            noise: Covariance::zeros(),
            response: SMatrix::zeros(),
            input: DriftInput::Unknown,
            s: 0.0,
            t,
        }
    }

    /// The input at time `t` with temperature `temp_c` (NaN: none), fixing its kind at the
    /// first sample after the reference.
    fn input(&mut self, t: f64, temp_c: f64) -> f64 {
        let t0 = *self.t.get_or_insert(t);
        if self.input == DriftInput::Unknown {
            self.input = if temp_c.is_finite() {
                DriftInput::Temperature(temp_c)
            } else {
                DriftInput::Time
            };
        }
        self.s = match self.input {
            DriftInput::Temperature(t_ref) if temp_c.is_finite() => temp_c - t_ref,
            // a thermometer that stops reading: the last change holds
            DriftInput::Temperature(_) => self.s,
            DriftInput::Time | DriftInput::Unknown => (t - t0) / 3600.0,
        };
        self.s
    }

    /// Through one update: `a` = I − K H, `kh` = K H, `krk` = K R̂ Kᵀ.
    fn advance(&mut self, a: &Covariance, kh: &Covariance, krk: &Covariance, t: f64, temp_c: f64) {
        let s = self.input(t, temp_c);
        self.phi = a * self.phi;
        let noise = a * self.noise * a.transpose() + krk;
        self.noise = (noise + noise.transpose()) * 0.5;
        self.response = a * self.response + kh.fixed_view::<N_STATE, N_PARAMS>(0, 0) * s;
    }

    /// The change's covariance under the linear noise model, (Φ − I) P_r (Φ − I)ᵀ + M, over
    /// the parameters (scaled units).
    fn covariance(&self) -> SMatrix<f64, N_PARAMS, N_PARAMS> {
        let phi = self.phi.fixed_view::<N_PARAMS, N_STATE>(0, 0)
            - Covariance::identity().fixed_view::<N_PARAMS, N_STATE>(0, 0);
        let cov =
            phi * self.cov * phi.transpose() + self.noise.fixed_view::<N_PARAMS, N_PARAMS>(0, 0);
        (cov + cov.transpose()) * 0.5
    }
}

/// The parameters' change since the reference and its covariance had nothing moved (mm, rad).
#[derive(Clone, Debug, PartialEq)]
pub struct Change {
    /// Time of the reference, s (None before the first sample).
    pub since_s: Option<f64>,
    /// Estimate now minus the estimate at the reference.
    pub dp: SVector<f64, N_PARAMS>,
    /// Its covariance under noise alone (see [`OnlineEstimator::change`]).
    pub cov: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// Column i: the estimate's change had parameter i crept by one unit (mm, rad) per unit
    /// of the input since the reference.
    pub response: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// What the creep follows, and its value now (K or h since the reference).
    pub input: DriftInput,
    pub input_now: f64,
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
    pub fn from_calibration(cal: &super::Calibration, opts: OnlineOptions) -> Self {
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
    pub fn change(&self) -> Change {
        let d = scale();
        let c = &self.change;
        let cov = c.covariance();
        Change {
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

    /// The motion that would settle the open tie: poses of `targets` (x, y mm) in order,
    /// chosen where the two estimates' predicted forces differ most against what either
    /// could make of the difference with its uncertain parameters ([`plan_motion`]), until
    /// the evidence expected is four times [`OnlineOptions::tie_evidence_chi2`] (the
    /// evidence a motion gives spreads by about twice its square root: short of the
    /// threshold less than once in 10⁴) or [`TIE_MOTION_POSES`] poses. None without an open tie or a
    /// reachable target.
    pub fn tie_motion(&self, targets: &[(f64, f64)]) -> Option<SeparatingMotion> {
        let tie = self.tie.as_ref()?;
        let mut named = self.clone();
        named.tie = None;
        let t = self.last_t.unwrap_or(0.0);
        let candidates: Vec<Candidate<N_STATE>> = targets
            .iter()
            .filter_map(|&(x, y)| {
                let q = crate::geometry::igm(&self.p, crate::params::Model::M29, x, y)
                    .ok()?
                    .q();
                let other = crate::elastic::fegm(&tie.alt.p, &tie.alt.stiffness(), q, ALL_ACTIVE)
                    .ok()?
                    .drive_force;
                // linearised against the runner-up's forces: the innovation is what the
                // named estimate's prediction misses of them
                let held = named.linearise(&ForceSample { t, q, f: other }).ok()?;
                Some(Candidate {
                    x,
                    y,
                    h: held.h,
                    r: held.r,
                    apart: -held.y,
                })
            })
            .collect();
        plan_motion(
            &candidates,
            &self.cov,
            4.0 * self.opts.tie_evidence_chi2,
            TIE_MOTION_POSES,
        )
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
        let gains = force_position_gains(&self.p, &k, s.q, &eq)?;
        let noise = self.opts.drives().modes(&gains);
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
        Ok(Held {
            sample: *s,
            h,
            y,
            r: noise.covariance(),
            info: noise.information(),
        })
    }

    fn innovation_cov(&self, held: &Held) -> Matrix4<f64> {
        held.h * self.cov * held.h.transpose() + held.r
    }

    /// Update with one linearised sample in information form (the information gained is
    /// added, never subtracted: a force row carries 10⁸ times the information of the prior
    /// in its direction, where the covariance form loses its positive definiteness); its
    /// normalised innovation.
    fn apply(&mut self, held: &Held) -> f64 {
        let nis = self.nis(held);
        let Some(prior) = self.cov.cholesky() else {
            return f64::NAN;
        };
        let ht_w = held.h.transpose() * held.info;
        let info = prior.inverse() + ht_w * held.h;
        let info = (info + info.transpose()) * 0.5;
        let Some(post) = info.cholesky() else {
            return f64::NAN;
        };
        let dx: SVector<f64, N_STATE> = post.solve(&(ht_w * held.y));
        let d = scale();
        for i in 0..N_PARAMS {
            self.p[i] += dx[i] * d[i];
        }
        self.dk += dx[STIFFNESS] * d[STIFFNESS];
        let cov = post.inverse();
        self.cov = (cov + cov.transpose()) * 0.5;
        self.track_change(held);
        self.applied += 1;
        nis
    }

    /// The change's covariance and the creep responses through one update's gain (see
    /// [`ChangeTrack`]).
    fn track_change(&mut self, held: &Held) {
        let h = &held.h;
        let k = self.cov * h.transpose() * held.info;
        let kh = k * h;
        let a = Covariance::identity() - kh;
        let t = self.last_t.unwrap_or(0.0);
        let seen = self
            .noise_seen
            .get_or_insert_with(|| ForceNoise::stated(&held.r));
        seen.add(&held.y);
        let krk = k * seen.covariance() * k.transpose();
        self.change.advance(&a, &kh, &krk, t, self.temp_c);
    }

    /// Normalised innovation of a linearised sample.
    fn nis(&self, held: &Held) -> f64 {
        let s = self.innovation_cov(held);
        let s = (s + s.transpose()) * 0.5;
        s.cholesky()
            .map_or(f64::INFINITY, |c| held.y.dot(&c.solve(&held.y)))
    }

    /// One decimated sample of the drives: predict, gate, update (or hold, or find a step);
    /// while a step is "this or that", both estimates predict the sample first and the
    /// evidence may tell them apart ([`Outcome::Resolved`]).
    pub fn update(&mut self, sample: &ForceSample) -> Result<Outcome, ElasticError> {
        let (held, named) = self.predicted(sample)?;
        let Some(mut tie) = self.tie.take() else {
            return self.decide(sample, &held, named.nis);
        };
        let Ok((alt_held, runner_up)) = tie.alt.predicted(sample) else {
            // the runner-up's model found no equilibrium here: a solver's failure is no
            // evidence about the machine, and the sample counts for neither
            tie.evidence.neither += 1;
            return self.after_tie(tie, sample, &held, named.nis);
        };
        tie.evidence
            .add(sample.t, sample.q, named, runner_up, GATE_CHI2_4);
        if tie.evidence.verdict(self.opts.tie_evidence_chi2) == Verdict::RunnerUp {
            std::mem::swap(self, &mut tie.alt);
            tie.swapped = true;
            return self.after_tie(tie, sample, &alt_held, runner_up.nis);
        }
        // the runner-up's estimate failing to take the sample is its own trouble, not the
        // named estimate's: the tie stays open, the sample counted for neither
        if tie.alt.decide(sample, &alt_held, runner_up.nis).is_err() {
            tie.evidence.neither += 1;
        }
        self.after_tie(tie, sample, &held, named.nis)
    }

    /// The sample through the estimate that stands after the tie's evidence: the resolution
    /// when the evidence decided it (unless the sample itself ends a step, which ends the
    /// tie), else the tie stays open.
    fn after_tie(
        &mut self,
        tie: Box<OpenTie>,
        sample: &ForceSample,
        held: &Held,
        nis: f64,
    ) -> Result<Outcome, ElasticError> {
        let verdict = tie.evidence.verdict(self.opts.tie_evidence_chi2);
        if verdict == Verdict::Open {
            self.tie = Some(tie);
            return self.decide(sample, held, nis);
        }
        let out = self.decide(sample, held, nis)?;
        if matches!(out, Outcome::Step(_)) {
            return Ok(out);
        }
        // the estimate moved where the runner-up stood: the drift test starts again
        if tie.swapped {
            self.rebase_change();
        }
        let at = tie
            .evidence
            .decisive
            .and_then(|d| self.tcp(d.q).ok())
            .map(|(x, _)| (x[0], x[1]));
        let (kept, ruled_out) = if tie.swapped {
            (tie.runner_up, tie.named)
        } else {
            (tie.named, tie.runner_up)
        };
        Ok(Outcome::Resolved(TieResolved {
            param: kept.0,
            change: kept.1,
            ruled_out: ruled_out.0,
            since_s: tie.since_s,
            swapped: tie.swapped,
            evidence: tie.evidence,
            at,
        }))
    }

    /// Predicts the sample at the estimate (after the drift allowed since the last): its
    /// linearised rows and how well the estimate predicted it.
    fn predicted(&mut self, sample: &ForceSample) -> Result<(Held, Prediction), ElasticError> {
        self.predict(sample.t);
        let held = self.linearise(sample)?;
        let s = self.innovation_cov(&held);
        let s = (s + s.transpose()) * 0.5;
        let prediction = s.cholesky().map_or(MISSED, |c| Prediction {
            nis: held.y.dot(&c.solve(&held.y)),
            ln_det: 2.0 * c.l().diagonal().iter().map(|v| v.ln()).sum::<f64>(),
        });
        Ok((held, prediction))
    }

    /// Gate, update (or hold, or find a step) with a predicted sample.
    fn decide(
        &mut self,
        sample: &ForceSample,
        held: &Held,
        nis: f64,
    ) -> Result<Outcome, ElasticError> {
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
                nis: self.apply(held),
            });
        }
        self.held.push(*held);
        if self.held.len() < self.opts.step_samples.max(1) {
            return Ok(Outcome::Held { nis });
        }
        let margin = self.attribute_step().margin;
        if margin < self.opts.step_margin && self.held.len() < self.opts.step_max_samples {
            return Ok(Outcome::Held { nis });
        }
        Ok(Outcome::Step(self.step_found()))
    }

    /// Names the step of the held samples, applies it, and the held samples after it; with
    /// a runner-up, a second estimate carrying the runner-up's change instead is kept until
    /// the evidence tells the two apart.
    fn step_found(&mut self) -> StepChange {
        // a new step ends any tie still open
        self.tie = None;
        let mut step = self.attribute_step();
        if step.margin >= self.opts.step_margin {
            step.alternative = None;
        }
        let alt = step.alternative.map(|b| {
            let (change, sigma) = self.one_parameter_fit(b);
            let mut alt = self.clone();
            alt.take_step(b, change, sigma);
            (alt, (b, change))
        });
        self.take_step(step.param, step.change, step.sigma);
        self.tie = alt.map(|(alt, runner_up)| {
            Box::new(OpenTie {
                alt,
                since_s: step.since_s,
                named: (step.param, step.change),
                runner_up,
                evidence: TieEvidence::default(),
                swapped: false,
            })
        });
        // the motion that would settle it, from what the two estimates know now
        step.separating = self.tie_motion(&crate::design::grid_231());
        step
    }

    /// Applies a step of `change` in state `param` (σ `sigma` from the held samples).
    fn take_step(&mut self, param: usize, change: f64, sigma: f64) {
        // the step itself, then the held samples through the filter with the parameter's
        // variance opened by a fifth of it (a one-parameter fit of a few poses is close,
        // not exact): spreading the whole step over every parameter the forces see alike
        // would move the ones they cannot tell apart
        self.set_state(param, self.state(param) + change);
        let c = 0.2 * change;
        self.cov[(param, param)] += (c * c + sigma * sigma) / scale()[param].powi(2);
        // the held samples are spent on the step's size: through the filter again they
        // would pull the combinations the forces cannot tell from the step (a start
        // covariance without its correlations leaves them free) and move the TCP
        self.held.clear();
        // a step is reported on its own: the drift test starts again from the estimate with it
        self.rebase_change();
    }

    /// The held samples' least-squares change of state `i` alone (mm, rad or relative) and
    /// its σ, in the forces at the currents' σ (see [`OnlineEstimator::attribute_step`]).
    fn one_parameter_fit(&self, i: usize) -> (f64, f64) {
        let (g, c) = self.held.iter().fold((0.0, 0.0), |(g, c), h| {
            let col = h.h.column(i);
            (g + col.dot(&h.y), c + col.dot(&col))
        });
        let w = self.opts.force_sigma_n.powi(-2);
        let d = scale()[i];
        if c > 0.0 {
            (g / c * d, (w * c).powf(-0.5) * d)
        } else {
            (0.0, f64::INFINITY)
        }
    }

    /// The single state that best explains the held innovations (least squares of each
    /// alone, in the forces themselves at the currents' σ): its change and margin.
    ///
    /// Not weighed by the drives' noise model as the update is: a crash's innovations are
    /// kN, far above any noise, and naming compares the candidates' signatures. The
    /// combinations the encoders' noise enters are where a crash shows; discounting them
    /// left the comparison to the combinations the currents' noise alone enters, where the
    /// rods' signatures are more alike (seed 7's crash of l4: 1.39x better than l5 that
    /// way, 1.78x in N).
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
            separating: None,
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

/// What explains a drift (see [`DriftMonitor::record`]): the candidate that explains it best
/// and every candidate that explains it as well within [`DRIFT_NAME_MARGIN`]. A slow drift
/// that the filter follows shows in the few combinations the forces pin, which every rod
/// length moves alike; there the best of the candidates is an accident of the path (on the
/// twin a creep of l3 was first named after l1 or l2 on three paths of four, with the wrong
/// sign on two), so one parameter is claimed only with the margin over all others.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Drift {
    /// Parameter index of the best.
    pub param: usize,
    /// How much better the best explains the drift than the runner-up (ratio of their χ²
    /// reductions).
    pub margin: f64,
    /// Per parameter: its change since the reference (mm or rad) where it is a candidate that
    /// explains the drift within [`DRIFT_NAME_MARGIN`] of the best (the best included), None
    /// for the others. One entry: the path names it; more: the path cannot tell which, and
    /// each has the change it would need (sizes and signs differ between them).
    pub candidates_alike: [Option<f64>; N_PARAMS],
    /// The best's creep per unit of the input (mm or rad per K, or per h without a
    /// temperature) and that rate's σ.
    pub rate: f64,
    pub rate_sigma: f64,
    /// What the rate is per.
    pub input: DriftInput,
    /// The best's change since the reference (the rate times the input now), mm or rad, and
    /// over how long, s.
    pub change: f64,
    pub over_s: f64,
    /// The share of the drift's χ² the best explains.
    pub explained: f64,
    /// How many parameters outside the candidates explain it as well (within
    /// [`DRIFT_NAME_MARGIN`]): a slow drift shows in the few combinations the forces pin,
    /// where a rod's length and its joints' positions across it move alike.
    pub alike: usize,
    /// Correlation of the best's track with the temperature (None without a temperature, or
    /// too few points).
    pub temperature_correlation: Option<f64>,
}

impl Drift {
    /// The candidates that explain it alike, each with its change (mm or rad): the best
    /// first, then the others in parameter order.
    pub fn named(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        let others = self
            .candidates_alike
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != self.param)
            .filter_map(|(i, c)| c.map(|c| (i, c)));
        std::iter::once((self.param, self.change)).chain(others)
    }

    /// Whether the path names one candidate alone.
    pub fn is_identified(&self) -> bool {
        self.named().count() == 1
    }
}

/// The drift test of the estimate's change since the reference, weighed in the covariance the
/// change would have had were nothing to have moved, after the expansion of the rods and
/// the frame (the `thermal` effect's two parts that are parameters, each at a rate of its
/// own, fitted) is taken out: how much of it a candidate's creep explains (`p_value`), and
/// beside it the χ² of all of it (`omnibus_p_value`, not tested).
///
/// Why the candidates and not the whole change: under noise alone the estimate wanders
/// beyond the linear noise model in a few combinations the forces pin to 0.01-0.4 µm, by µm
/// in half an hour, and slowly (its rate estimated from the increments over 10 s, 1 min or 3
/// min, their covariance about their mean less the model's, took out none of it), the same
/// from a start at the twin's truth as from a calibration's and at constant temperature: the
/// χ² of the whole change reached 1,300 on 27 dof in 40 minutes of the twin's hour. What a
/// rod's creep explains of the change stays χ²₁ under noise alone over the hour (p < 0.01 at
/// 0.8 % of the checks, < 0.5 at 47 %, seed 43; 0 % and 20 % on seed 7: conservative).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DriftTest {
    pub chi2: f64,
    /// Degrees of freedom: the combinations the forces have determined since the reference,
    /// less the expansion's.
    pub dof: usize,
    /// P(χ²_dof ≥ chi2): the probability that noise alone moved the estimate this far in
    /// any direction. Not what warns: under noise alone the estimate wanders beyond the
    /// linear noise model in combinations no candidate's creep moves (χ² 1,300 on 27 dof
    /// after 40 minutes of the twin's hour), so over hours this is no test.
    pub omnibus_p_value: f64,
    /// P(noise alone): that a candidate's creep explains this much of the change (see
    /// [`DriftMonitor::record`]): what [`DriftTest::warning`] tests.
    pub p_value: f64,
    /// The fitted expansion of the rods and of the frame, per unit of the input, ppm (NaN
    /// where the forces did not see it).
    pub expansion_ppm: [f64; 2],
    /// Per parameter, the χ² its creep alone explains of the rest, and its rate (mm or rad
    /// per unit of the input): a slow drift shows in the few combinations the forces pin, so
    /// several parameters may explain it alike.
    pub explains: [f64; N_PARAMS],
    pub rates: [f64; N_PARAMS],
    /// The candidate that explains the rest best (None before the forces saw anything).
    pub best: Option<Drift>,
}

impl DriftTest {
    /// The drift to warn about: significant at [`DRIFT_FALSE_ALARM`] and the best candidate's
    /// change beyond `threshold_mm` (rad: `threshold_mm` / 1000), so that a µm the forces
    /// resolve is not a WARN (the others alike are told with their own changes, which differ
    /// in size and sign: see [`Drift`]).
    pub fn warning(&self, threshold_mm: f64) -> Option<&Drift> {
        let d = self.best.as_ref()?;
        let threshold = match unit(d.param) {
            Unit::Mm => threshold_mm,
            Unit::Rad => threshold_mm / 1000.0,
        };
        (self.p_value < DRIFT_FALSE_ALARM && d.change.abs() > threshold).then_some(d)
    }
}

/// False-alarm probability of one drift test under noise alone (a check a second: at most
/// 0.4 % per hour by the union bound, less as successive checks share their data), on the
/// candidates' p ([`DriftTest::p_value`]).
pub const DRIFT_FALSE_ALARM: f64 = 1e-6;
/// A drift is named alone when its parameter explains it this many times better than the
/// next (as [`OnlineOptions::step_margin`]).
pub const DRIFT_NAME_MARGIN: f64 = 1.5;
/// Eigenvalues of the change's covariance below this fraction of the largest are
/// combinations the forces have not determined (scaled units: rounding sits near 1e-16).
const DRIFT_RANK_CUTOFF: f64 = 1e-12;

/// Correlation with the temperature from which a drift "follows" it.
pub const FOLLOWS: f64 = 0.9;

/// Whitened vectors of the drift test: the change and the creep responses in the eigenbasis
/// of the change's covariance, scaled to unit variance, the combinations the forces have not
/// determined (no variance: the estimate does not move along them) dropped.
struct Whitened {
    w: SMatrix<f64, N_PARAMS, N_PARAMS>,
    z: SVector<f64, N_PARAMS>,
    cols: SMatrix<f64, N_PARAMS, N_PARAMS>,
    rank: usize,
}

impl Whitened {
    fn new(c: &Change) -> Whitened {
        let d = scale();
        let cov = SMatrix::<f64, N_PARAMS, N_PARAMS>::from_fn(|i, j| c.cov[(i, j)] / (d[i] * d[j]));
        let eig = cov.symmetric_eigen();
        let top = eig.eigenvalues.max();
        let mut w = eig.eigenvectors.transpose();
        let mut rank = 0;
        for (k, &l) in eig.eigenvalues.iter().enumerate() {
            let keep = top > 0.0 && l > DRIFT_RANK_CUTOFF * top;
            rank += usize::from(keep);
            let f = if keep { l.sqrt().recip() } else { 0.0 };
            w.row_mut(k).scale_mut(f);
        }
        let dp = SVector::<f64, N_PARAMS>::from_fn(|i, _| c.dp[i] / d[i]);
        let resp =
            SMatrix::<f64, N_PARAMS, N_PARAMS>::from_fn(|j, i| c.response[(j, i)] / d[j] * d[i]);
        Whitened {
            z: w * dp,
            cols: w * resp,
            w,
            rank,
        }
    }
}

/// One parameter's creep against the rest of the change: its whitened response with the
/// expansion taken out, its least-squares rate (scaled units per unit of the input) and the
/// χ² it explains.
type CreepFit = (SVector<f64, N_PARAMS>, f64, f64);

/// Each parameter's creep fitted alone to the rest `z` of the change.
fn creep_fits(
    w: &Whitened,
    basis: &[SVector<f64, N_PARAMS>],
    z: &SVector<f64, N_PARAMS>,
) -> Vec<CreepFit> {
    (0..N_PARAMS)
        .map(|i| {
            let mut u: SVector<f64, N_PARAMS> = w.cols.column(i).into_owned();
            project_out(&mut u, basis);
            let info = u.norm_squared();
            let g = u.dot(z);
            if info > 0.0 {
                (u, g / info, g * g / info)
            } else {
                (u, 0.0, 0.0)
            }
        })
        .collect()
}

/// P(noise alone explains this much by a candidate's creep): the best candidate's χ²
/// reduction (1 dof) over as many independent tests as the candidates make (their creeps
/// through the filter are nearly parallel: rods 1 to 5 alike in the combinations the forces
/// pin), by the effective number of tests of their correlation matrix's eigenvalues (Li and
/// Ji 2005: each eigenvalue counts 1 if at least 1, plus its fractional part), Šidák.
fn candidates_p(fits: &[CreepFit], candidates: &[usize], dof: usize) -> f64 {
    let seen: Vec<&CreepFit> = candidates
        .iter()
        .filter(|&&i| i < N_PARAMS && fits[i].0.norm_squared() > 0.0)
        .map(|&i| &fits[i])
        .collect();
    let best = seen.iter().map(|f| f.2).fold(0.0, f64::max);
    if dof == 0 || best <= 0.0 {
        return 1.0;
    }
    let m = seen.len();
    let corr = nalgebra::DMatrix::from_fn(m, m, |a, b| {
        let (u, v) = (&seen[a].0, &seen[b].0);
        u.dot(v) / (u.norm() * v.norm())
    });
    let tests: f64 = corr
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .map(|l| {
            let l = l.abs();
            f64::from(u8::from(l >= 1.0)) + l.fract()
        })
        .sum::<f64>()
        .max(1.0);
    let p1 = crate::stats::chi2_upper_tail(best, 1.0);
    // 1 − (1 − p1)^tests without losing a small p1
    -(tests * (-p1).ln_1p()).exp_m1()
}

/// Removes from `v` its components along the orthonormal `basis`.
fn project_out(v: &mut SVector<f64, N_PARAMS>, basis: &[SVector<f64, N_PARAMS>]) {
    for q in basis {
        let c = q.dot(v);
        *v -= q * c;
    }
}

/// The expansion of the rods and of the frame as creeps of their lengths, ppm of each.
fn expansion_directions(p: &Params) -> [SVector<f64, N_PARAMS>; 2] {
    let mut rods = SVector::zeros();
    for r in &crate::params::RODS {
        rods[r.l] = p[r.l] * 1e-6 / scale()[r.l];
    }
    let mut frame = SVector::zeros();
    for i in [crate::params::D1, crate::params::D2] {
        frame[i] = p[i] * 1e-6 / scale()[i];
    }
    [rods, frame]
}

/// Stream time after the start (or a step) before the drift test takes its reference, s:
/// until the forces have determined what they can of the start error, a change since the
/// start is mostly the start error corrected, which noise alone would explain as well as a
/// drift.
pub const DRIFT_SETTLE_S: f64 = 30.0;

/// The same after a step, s: the step is named from a few samples, and the combination its
/// naming could not tell apart (rods 1 and 3 move the forces alike) settles over minutes
/// after it, which a reference taken at 30 s reports as a drift (p 10⁻⁸ 36 s after the
/// reference on the twin's hour, the crash named "l3 or l1"; none past 150 s).
pub const DRIFT_SETTLE_AFTER_STEP_S: f64 = 300.0;

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

    /// Which parameters a drift is named among (the rod lengths by default, as a step: a
    /// clamping that slips, a rod that bends as it warms).
    #[must_use]
    pub fn with_candidates(mut self, candidates: StepCandidates) -> DriftMonitor {
        self.candidates = candidates;
        self
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
    fn test(&self, change: &Change) -> DriftTest {
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
    fn name(&self, w: &Whitened, fits: &[CreepFit], chi2: f64, change: &Change) -> Option<Drift> {
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

#[cfg(test)]
mod tests {

    use super::*;
    use rand::{rngs::StdRng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// A tie told apart by the samples at the pose the tracker names, whichever of the two
    /// it named: the machine's forces from the elastic model at the true parameters (l3
    /// crashed by 0.1 mm), 5 N of noise; the tie built as a step would leave it, the named
    /// estimate with l1's change that best reproduces the crash at the workspace centre.
    /// The machine of these tests: forces from the elastic model at the true parameters,
    /// 5 N of noise, a sample every 0.1 s.
    struct Machine {
        truth: Params,
        rng: StdRng,
        t: f64,
    }

    impl Machine {
        fn new(truth: Params) -> Machine {
            Machine {
                truth,
                rng: StdRng::seed_from_u64(28),
                t: 0.0,
            }
        }

        /// One sample at the pose (x, y mm), commanded by the nominal machine's igm.
        fn sample(&mut self, (x, y): (f64, f64)) -> ForceSample {
            let q = crate::geometry::igm(&Params::nominal(), crate::params::Model::M29, x, y)
                .expect("reachable")
                .q();
            let f = crate::elastic::fegm(&self.truth, &Stiffness::default(), q, ALL_ACTIVE)
                .expect("there")
                .drive_force;
            let noise = Normal::new(0.0, 5.0).expect("normal");
            self.t += 0.1;
            ForceSample {
                t: self.t,
                q,
                f: f.map(|v| v + noise.sample(&mut self.rng)),
            }
        }
    }

    fn tied(named_is_l3: bool) -> (OnlineEstimator, Params) {
        use crate::params::{L1, L3};
        let start = Params::nominal();
        let mut truth = start;
        truth[L3] += 0.1;
        let sigmas: [f64; N_PARAMS] =
            std::array::from_fn(|i| if unit(i) == Unit::Mm { 0.002 } else { 2e-5 });
        let est = OnlineEstimator::from_sigmas(start, Some(&sigmas), OnlineOptions::default());
        let k = est.stiffness();
        let (cx, cy) = crate::design::CENTRE;
        let q = crate::geometry::igm(&start, crate::params::Model::M29, cx, cy)
            .expect("centre")
            .q();
        let (eq, dp) = force_jacobian(&start, &k, q, None).expect("forces");
        let moved = crate::elastic::fegm(&truth, &k, q, ALL_ACTIVE).expect("crashed");
        let df = Vector4::from_fn(|a, _| moved.drive_force[a] - eq.drive_force[a]);
        let col = Vector4::from_fn(|a, _| dp[a][L1]);
        let l1_change = col.dot(&df) / col.dot(&col);
        let (named, other) = if named_is_l3 {
            ((L3, 0.1), (L1, l1_change))
        } else {
            ((L1, l1_change), (L3, 0.1))
        };
        let mut est_named = est.clone();
        est_named.take_step(named.0, named.1, 0.0);
        let mut alt = est;
        alt.take_step(other.0, other.1, 0.0);
        est_named.tie = Some(Box::new(OpenTie {
            alt,
            since_s: 0.0,
            named,
            runner_up: other,
            evidence: TieEvidence::default(),
            swapped: false,
        }));
        (est_named, truth)
    }

    fn settle(named_is_l3: bool) -> (TieResolved, Params) {
        let (est_named, truth) = tied(named_is_l3);
        let motion = est_named
            .tie_motion(&crate::design::grid_231())
            .expect("a motion");
        assert!(motion.chi2 >= 4.0 * TIE_EVIDENCE_CHI2, "{motion:?}");
        let mut machine = Machine::new(truth);
        let mut est = est_named;
        for &pose in &motion.poses {
            // three samples at each pose, as a cell stops there briefly
            for _ in 0..3 {
                if let Outcome::Resolved(r) = est.update(&machine.sample(pose)).expect("update") {
                    assert!(est.tie().is_none());
                    eprintln!("{motion:?}: {r:?}");
                    return (r, *est.params());
                }
            }
        }
        panic!("not settled by {motion:?}: {:?}", est.tie());
    }

    /// One pose, however long the machine stays there, does not settle the tie: 50 samples at
    /// the motion's first pose leave the evidence short of the threshold (both estimates
    /// absorb the difference with parameters that pose cannot pin), where the motion's
    /// poses settle it in a few.
    #[test]
    fn a_single_pose_does_not_settle_a_tie() {
        let (mut est, truth) = tied(true);
        let motion = est
            .tie_motion(&crate::design::grid_231())
            .expect("a motion");
        let mut machine = Machine::new(truth);
        for _ in 0..50 {
            let out = est
                .update(&machine.sample(motion.poses[0]))
                .expect("update");
            assert!(!matches!(out, Outcome::Resolved(_)), "{out:?}");
        }
        let so_far = est.tie().expect("still open").evidence;
        eprintln!("50 samples at {:?}: {so_far:?}", motion.poses[0]);
        assert!(so_far.chi2.abs() < TIE_EVIDENCE_CHI2, "{so_far:?}");
        assert_eq!(so_far.counted, 50);
    }

    #[test]
    fn a_tie_named_right_is_kept() {
        use crate::params::{L1, L3};
        let (r, p) = settle(true);
        assert_eq!((r.param, r.ruled_out, r.swapped), (L3, L1, false), "{r:?}");
        assert!(r.evidence.chi2 >= TIE_EVIDENCE_CHI2, "{r:?}");
        assert!(
            (p[L3] - Params::nominal()[L3] - 0.1).abs() < 0.01,
            "l3 {}",
            p[L3]
        );
    }

    #[test]
    fn a_tie_named_wrong_is_swapped() {
        use crate::params::{L1, L3};
        let (r, p) = settle(false);
        assert_eq!((r.param, r.ruled_out, r.swapped), (L3, L1, true), "{r:?}");
        assert!(r.evidence.chi2 <= -TIE_EVIDENCE_CHI2, "{r:?}");
        let nominal = Params::nominal();
        assert!((p[L3] - nominal[L3] - 0.1).abs() < 0.01, "l3 {}", p[L3]);
        assert!((p[L1] - nominal[L1]).abs() < 0.01, "l1 {}", p[L1]);
    }

    /// The force noise from successive innovations is the noise, not the filter's lag: a
    /// slow bias on top of white noise (3 N and 7 N on two drives) leaves its estimate at the
    /// noise's variance, where the innovations' own mean square takes the bias for noise.
    #[test]
    fn force_noise_ignores_a_slow_bias() {
        let mut rng = StdRng::seed_from_u64(15);
        let sigma = Vector4::new(3.0, 7.0, 3.0, 3.0);
        let unit = Normal::new(0.0, 1.0).expect("normal");
        let mut seen = ForceNoise::stated(&(Matrix4::identity() * 25.0));
        let mut mean_square = Matrix4::zeros();
        let n = 20_000;
        for k in 0..n {
            let lag = 20.0 * (f64::from(k) / 2000.0).sin();
            let y = Vector4::from_fn(|a, _| lag + sigma[a] * unit.sample(&mut rng));
            seen.add(&y);
            mean_square += y * y.transpose() / f64::from(n);
        }
        let r = seen.covariance();
        for a in 0..4 {
            let truth = sigma[a] * sigma[a];
            assert!((r[(a, a)] / truth - 1.0).abs() < 0.05, "drive {a}: {r}");
            assert!(mean_square[(a, a)] > truth + 150.0, "{mean_square}");
        }
        assert!(r[(0, 1)].abs() < 0.05 * 21.0, "{r}");
    }
}
