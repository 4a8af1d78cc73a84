//! The digital twin of the Scissors-Kinematics: a simulated machine and measurement cell that
//! produces campaigns in the spec's CSV model, deterministically from a seed.
//!
//! - True machine: nominal parameters + seeded errors (σ 0.1 mm on lengths, 0.2 mrad on
//!   angles), with a perfect parallel-holder ([`Params::with_perfect_parallelogram`]) unless the
//!   `parallelogram` effect is on, so model 24 describes effect-free data exactly.
//! - Controller: commands igm of its own parameters (the nominal ones by default).
//! - Drives: q1, q4 position-controlled, q2, q3 followers (rigid geometry: the pose is the true
//!   fgm(q1, q4), followers read the true rgm); under `preload_elastic` all four are
//!   position-controlled and pose and drive forces come from the elasto-geometric model.
//!   `self` poses always switch q2, q3 to followers, and so does a pose planned in that mode
//!   ([`PlannedPose::follower`]).
//! - Encoders and instruments with the twin's own noise ([`TwinConfig::noise`]), which a test
//!   sets apart from what the calibration assumes.
//! - Relative setups: the reset pose records 0, the others true TCP − true reset TCP, plus
//!   their own noise minus the noise of the reading the instrument was zeroed on (a tracker,
//!   grid encoder or interferometer is zeroed on a reading as noisy as any other, shared by
//!   every reading of the setup; [`ResetReading::Exact`] zeroes on the truth); ball-bar r is
//!   the distance to the pivot (the reset pose's TCP, where the machine stood). An
//!   instrument may drift after its zero ([`ZeroDrift`]: its readings carry a rate times the
//!   time since their setup's reset pose).
//! - Covariate `temp_machine` (°C) and time `t` (s): 3 s per pose, 120 s between setups; the
//!   clock runs on across campaigns, so a later validation campaign is later in time.
//!
//! Every effect is applied per pose as effective parameters (temperature, bow) and a map from
//! encoder reading to carrier position (thermal expansion of the scale, scale error).

pub mod effects;
mod instrument;
mod machine;
pub mod production;
mod stream;

pub use effects::EffectKind;
use machine::gauss;
pub use machine::{
    CyclicScale, MachineState, ResetReading, ThermalPhysics, Twin, TwinConfig, TwinError,
    ZeroDrift, SECONDS_BETWEEN_SETUPS, SECONDS_PER_POSE, TEMP_SENSOR_K,
};
pub use production::{
    Creep, ProductionConfig, ProductionSample, ProductionStream, StepChange, TimeCreep, Visit,
};
pub use stream::{DriveSample, DriveStream};

use effects::{bow, THERMAL_PERIOD_S};
use nalgebra::Vector2;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rpkm_core::campaign::{Campaign, Instrument, MeasuredPose};
use rpkm_core::design::{self, PlannedPose};
use rpkm_core::elastic::{self, Stiffness, ALL_ACTIVE};
use rpkm_core::geometry::{self};
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{self, Model, Params, NAMES, N_PARAMS, RODS};
use rpkm_core::units::{fraction_from_ppm, rad_from_mrad};
use std::collections::BTreeMap;

/// Everything the twin hid, for a report or a test (serde: JSON with parameter names).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Truth {
    pub seed: u64,
    /// True parameters at 20 °C, by name (mm, rad).
    pub params: BTreeMap<String, f64>,
    /// Parameters of the controller, by name.
    pub controller: BTreeMap<String, f64>,
    pub stiffness: Stiffness,
    /// Effects with their magnitudes.
    pub effects: Vec<EffectTruth>,
    pub length_sigma_mm: f64,
    pub angle_sigma_rad: f64,
    /// Instrument rotation of each setup measured so far, rad (`instrument_alignment`).
    pub alignment_rad: BTreeMap<String, f64>,
    /// Thermal model: α of the rods (1/K), reference °C, swing period s, and every part's α.
    pub alpha_per_k: f64,
    pub reference_temp_c: f64,
    pub thermal_period_s: f64,
    pub thermal: ThermalPhysics,
    /// The instrument that drifted after its zero, and how fast ([`TwinConfig::drift`]).
    #[serde(default)]
    pub drift: Option<ZeroDrift>,
}

/// One effect of a [`Truth`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EffectTruth {
    pub effect: EffectKind,
    pub magnitude: f64,
    pub unit: String,
}

fn by_name(p: &Params) -> BTreeMap<String, f64> {
    NAMES
        .iter()
        .enumerate()
        .map(|(i, n)| ((*n).to_owned(), p[i]))
        .collect()
}

/// FNV-1a of a string, to seed per-setup draws independently of the order of campaigns.
fn fnv(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

impl Twin {
    /// Build a twin: draws the true machine from the seed.
    pub fn new(config: TwinConfig) -> Result<Twin, TwinError> {
        for (k, (e, m)) in config.effects.iter().enumerate() {
            if config.effects[..k].iter().any(|(o, _)| o == e) {
                return Err(TwinError::DuplicateEffect(*e));
            }
            if !m.is_finite() {
                return Err(TwinError::BadMagnitude {
                    effect: *e,
                    magnitude: *m,
                    extra: "",
                });
            }
            if *e == EffectKind::PreloadElastic && !(*m > 0.0) {
                return Err(TwinError::BadMagnitude {
                    effect: *e,
                    magnitude: *m,
                    extra: " > 0",
                });
            }
        }
        if let Some(d) = &config.drift {
            instrument::check_drift(d)?;
        }
        let mut rng = StdRng::seed_from_u64(config.seed);
        let mut p = Params::nominal();
        for i in 0..N_PARAMS {
            let sigma = match params::unit(i) {
                params::Unit::Mm => config.length_sigma_mm,
                params::Unit::Rad => config.angle_sigma_rad,
            };
            p[i] += sigma * gauss(&mut rng);
        }
        p = p.with_perfect_parallelogram();
        let noise_seed = config.noise_seed.unwrap_or(config.seed);
        let twin = Twin {
            rng: StdRng::seed_from_u64(noise_seed ^ 0x9e37_79b9_7f4a_7c15),
            force_rng: StdRng::seed_from_u64(noise_seed ^ 0xf0e5_c0de_0000_0004),
            reset_rng: StdRng::seed_from_u64(noise_seed ^ 0x7e5e_7000_0000_0005),
            guide_rng: StdRng::seed_from_u64(noise_seed ^ 0x6d1d_e000_0000_0007),
            t: 0.0,
            alignment: BTreeMap::new(),
            truth_params: p,
            config,
        };
        let mut twin = twin;
        if let Some(m) = twin.magnitude(EffectKind::Parallelogram) {
            twin.truth_params[params::L5] += m;
        }
        Ok(twin)
    }

    /// Magnitude of an effect, if on.
    pub fn magnitude(&self, e: EffectKind) -> Option<f64> {
        self.config
            .effects
            .iter()
            .find(|(k, _)| *k == e)
            .map(|(_, m)| *m)
    }

    /// The true parameters at the reference temperature.
    pub fn true_params(&self) -> &Params {
        &self.truth_params
    }

    /// The machine changes between campaigns: a crash bends a rod, a part wears or creeps.
    /// Parameter `param`'s true value moves by `by` (mm, rad) for every campaign after this;
    /// false (nothing moved) for an index that is no parameter.
    pub fn shift(&mut self, param: usize, by: f64) -> bool {
        match self.truth_params.0.get_mut(param) {
            Some(v) => {
                *v += by;
                true
            }
            None => false,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &TwinConfig {
        &self.config
    }

    /// Current time of the twin's clock, s.
    pub fn time(&self) -> f64 {
        self.t
    }

    /// The true machine temperature at time t, °C.
    pub fn temperature(&self, t: f64) -> f64 {
        match self.magnitude(EffectKind::Thermal) {
            Some(a) => {
                self.config.thermal.reference_c
                    - a * (std::f64::consts::TAU * t / THERMAL_PERIOD_S).cos()
            }
            None => self.config.thermal.reference_c,
        }
    }

    /// What the machine thermometer reads at time t without its noise, °C: the true
    /// temperature through the thermometers' first-order lag
    /// ([`ThermalPhysics::thermometer_lag_s`]). For the swing T_ref − a cos ωt from
    /// equilibrium at t = 0 the lag is exact: the swing's steady response
    /// −a (cos ωt + ωτ sin ωt)/(1 + ω²τ²) and the transient that starts it at T(0).
    pub fn thermometer(&self, t: f64) -> f64 {
        let th = &self.config.thermal;
        let tau = th.thermometer_lag_s;
        let Some(a) = self.magnitude(EffectKind::Thermal).filter(|_| tau > 0.0) else {
            return self.temperature(t);
        };
        let w = std::f64::consts::TAU / THERMAL_PERIOD_S;
        let wt = w * tau;
        let den = 1.0 + wt * wt;
        let steady = -a * ((w * t).cos() + wt * (w * t).sin()) / den;
        let transient = -a * wt * wt / den * (-t / tau).exp();
        th.reference_c + steady + transient
    }

    /// What guide `g`'s thermometer reads at time t without its noise, °C (see
    /// [`Twin::thermometer`]; a guide's departure is the mean's scaled, and so is its lag).
    pub fn guide_thermometer(&self, g: usize, t: f64) -> f64 {
        let th = &self.config.thermal;
        th.reference_c + th.guide_rates[g] * (self.thermometer(t) - th.reference_c)
    }

    /// The true temperature of guide `g` (0: guide 1, 1: guide 2) at time t, °C: the mean's
    /// departure from the reference scaled by the guide's rate.
    pub fn guide_temperature(&self, g: usize, t: f64) -> f64 {
        let th = &self.config.thermal;
        th.reference_c + th.guide_rates[g] * (self.temperature(t) - th.reference_c)
    }

    /// Stiffness of the true machine.
    pub fn stiffness(&self) -> Stiffness {
        self.config.stiffness
    }

    /// The parameters the controller commands igm with: its own, or under `preload_elastic`
    /// (all drives active, so not for self-calibration poses) the true ones plus the magnitude
    /// times its error.
    fn controller(&self, followers_23: bool) -> Params {
        let c = self.config.controller;
        match self.magnitude(EffectKind::PreloadElastic) {
            Some(m) if !followers_23 => {
                let mut p = self.truth_params;
                for i in 0..N_PARAMS {
                    p[i] += m * (c[i] - p[i]);
                }
                p
            }
            _ => c,
        }
    }

    /// Everything hidden.
    pub fn truth(&self) -> Truth {
        Truth {
            seed: self.config.seed,
            params: by_name(&self.truth_params),
            controller: by_name(&self.controller(false)),
            stiffness: self.stiffness(),
            effects: self
                .config
                .effects
                .iter()
                .map(|(e, m)| EffectTruth {
                    effect: *e,
                    magnitude: *m,
                    unit: e.unit().to_owned(),
                })
                .collect(),
            length_sigma_mm: self.config.length_sigma_mm,
            angle_sigma_rad: self.config.angle_sigma_rad,
            alignment_rad: self.alignment.clone(),
            alpha_per_k: self.config.thermal.rods_per_k,
            reference_temp_c: self.config.thermal.reference_c,
            thermal_period_s: THERMAL_PERIOD_S,
            thermal: self.config.thermal,
            drift: self.config.drift,
        }
    }

    /// Effective parameters at time `t` with guide-2 carriers at s1, s4 (bow): the rods at
    /// the machine's temperature, each half of the frame at its guide's.
    fn effective(&self, t: f64, s1: f64, s4: f64) -> Params {
        let mut p = self.truth_params;
        let th = self.config.thermal;
        let dt = self.temperature(t) - th.reference_c;
        if dt != 0.0 {
            for rod in &RODS {
                p[rod.l] *= 1.0 + th.rods_per_k * dt;
            }
            p[params::D1] *= 1.0 + th.frame_per_k * (self.guide_temperature(0, t) - th.reference_c);
            p[params::D2] *= 1.0 + th.frame_per_k * (self.guide_temperature(1, t) - th.reference_c);
        }
        if let Some(m) = self.magnitude(EffectKind::GuideStraightness) {
            p[params::XB1R] += bow(m, s1);
            p[params::XB4R] += bow(m, s4);
            p[params::XB5R] += bow(m, s4);
        }
        p
    }

    /// Factors carrier position / encoder reading of the four drives at time `t`: each scale
    /// at its guide's temperature (carriers 2, 3 on guide 1; 1, 4 on guide 2).
    fn scale(&self, t: f64) -> [f64; 4] {
        let th = self.config.thermal;
        let at = |g: usize| 1.0 + th.scales_per_k * (self.guide_temperature(g, t) - th.reference_c);
        let g2 = 1.0 + fraction_from_ppm(self.magnitude(EffectKind::EncoderScale).unwrap_or(0.0));
        [at(1) * g2, at(0), at(0), at(1) * g2]
    }

    /// Drive the true machine to the controller's command for target (x, y) at time t, with
    /// encoder reading errors `enc` (mm) on the active drives. `followers_23` switches q2, q3
    /// to followers (self-calibration) even under `preload_elastic`.
    pub fn machine_state(
        &self,
        setup: &str,
        x: f64,
        y: f64,
        t: f64,
        enc: [f64; 4],
        followers_23: bool,
    ) -> Result<MachineState, TwinError> {
        let cmd = geometry::igm(&self.controller(followers_23), Model::M29, x, y)
            .map_err(|source| TwinError::Controller {
                setup: setup.to_owned(),
                x,
                y,
                source,
            })?
            .q();
        let sc = self.scale(t);
        let elastic_on = self.magnitude(EffectKind::PreloadElastic).is_some() && !followers_23;
        // True carrier positions of the active drives.
        let mut s = [0, 1, 2, 3].map(|i| (cmd[i] + enc[i]) * sc[i]);
        if let Some(c) = self.config.cyclic.filter(|c| c.carrier < 4) {
            s[c.carrier] += c.offset(cmd[c.carrier] + enc[c.carrier]);
        }
        let p = self.effective(t, s[0], s[3]);
        if elastic_on {
            let eq = elastic::fegm(&p, &self.stiffness(), s, ALL_ACTIVE).map_err(|source| {
                TwinError::Elastic {
                    setup: setup.to_owned(),
                    x,
                    y,
                    source,
                }
            })?;
            return Ok(MachineState {
                tcp: Vector2::new(eq.x, eq.y),
                psi: eq.psi,
                q: cmd,
                f: eq.drive_force,
                follower: [false; 4],
            });
        }
        let sol =
            geometry::fgm(&p, Model::M29, s[0], s[3]).map_err(|source| TwinError::Machine {
                setup: setup.to_owned(),
                x,
                y,
                source,
            })?;
        let c = sol.q();
        let mut q = [cmd[0], c[1] / sc[1], c[2] / sc[2], cmd[3]];
        // a follower reads its position less its scale's error (to first order in an
        // amplitude of µm against a pitch of mm)
        if let Some(cy) = self
            .config
            .cyclic
            .filter(|c| c.carrier == 1 || c.carrier == 2)
        {
            q[cy.carrier] -= cy.offset(q[cy.carrier]);
        }
        Ok(MachineState {
            tcp: Vector2::new(sol.x(), sol.y()),
            psi: sol.psi(),
            q,
            f: [0.0; 4],
            follower: [false, true, true, false],
        })
    }

    fn alignment_angle(&mut self, setup: &str) -> f64 {
        let Some(m) = self.magnitude(EffectKind::InstrumentAlignment) else {
            return 0.0;
        };
        let seed = self.config.seed;
        *self.alignment.entry(setup.to_owned()).or_insert_with(|| {
            let mut r = StdRng::seed_from_u64(seed ^ fnv(setup));
            rad_from_mrad(m) * gauss(&mut r)
        })
    }

    /// Direction (±1) of the last move of q1 and q4 at `plan`'s command, carried in
    /// `approach` (last command, direction) from pose to pose.
    fn approach_direction(
        &self,
        plan: &PlannedPose,
        self_cal: bool,
        approach: &mut Option<([f64; 2], [f64; 2])>,
    ) -> Result<[f64; 2], TwinError> {
        let cmd = geometry::igm(&self.controller(self_cal), Model::M29, plan.x, plan.y)
            .map_err(|source| TwinError::Controller {
                setup: plan.setup.clone(),
                x: plan.x,
                y: plan.y,
                source,
            })?
            .q();
        let now = [cmd[0], cmd[3]];
        let (last, mut dir) = approach.unwrap_or((now, [1.0, 1.0]));
        for j in 0..2 {
            if (now[j] - last[j]).abs() > 1e-9 {
                dir[j] = (now[j] - last[j]).signum();
            }
        }
        *approach = Some((now, dir));
        Ok(dir)
    }

    /// A pose's drive readings: the commanded positions, the followers' encoders (noise σ
    /// `encoder_mm`), the drive forces and the temperature sensor, with the approach
    /// `covariates` after the temperature. `k` scales the noise (0: noiseless, the draws still
    /// made). No instrument reading yet.
    fn drive_readings(
        &mut self,
        plan: &PlannedPose,
        t: f64,
        st: &MachineState,
        (k, encoder_mm): (f64, f64),
        mut covariates: Vec<Option<f64>>,
    ) -> MeasuredPose {
        let mut q = st.q;
        for (qi, &follower) in q.iter_mut().zip(&st.follower) {
            if follower {
                *qi += k * encoder_mm * gauss(&mut self.rng);
            }
        }
        let temp = self.thermometer(t) + k * TEMP_SENSOR_K * gauss(&mut self.rng);
        covariates.insert(0, Some(temp));
        if self.config.thermal.guide_thermometers {
            // their own draws after every other: the readings stay the same with or without
            for (slot, g) in [(1, 0), (2, 1)] {
                let reading =
                    self.guide_thermometer(g, t) + k * TEMP_SENSOR_K * gauss(&mut self.guide_rng);
                covariates.insert(slot, Some(reading));
            }
        }
        MeasuredPose {
            t,
            setup: plan.setup.clone(),
            instrument: plan.instrument,
            reset: plan.reset,
            q,
            f: st.f,
            follower: st.follower,
            x: None,
            y: None,
            r: None,
            psi: None,
            covariates,
            line: 0,
        }
    }

    /// Measure a design on the twin: one campaign, `source` labelling it.
    pub fn run(&mut self, design: &[PlannedPose], source: &str) -> Result<Campaign, TwinError> {
        // noiseless: the spec's levels times zero, so that the draws stay the same
        let (k, noise) = match &self.config.noise {
            Some(n) => (1.0, n.clone()),
            None => (0.0, NoiseModel::default()),
        };
        let mut poses = Vec::with_capacity(design.len());
        let mut zeroed: Option<instrument::Zeroed> = None;
        let mut last_setup: Option<&str> = None;
        let backlash = self.magnitude(EffectKind::Backlash);
        let lost_q4 = self.magnitude(EffectKind::LostMotionQ4);
        // last command and approach direction of q1, q4 (backlash, lost motion)
        let mut approach: Option<([f64; 2], [f64; 2])> = None;
        for (n, plan) in design.iter().enumerate() {
            if last_setup.is_some_and(|s| s != plan.setup) {
                self.t += SECONDS_BETWEEN_SETUPS;
            }
            last_setup = Some(&plan.setup);
            self.t += SECONDS_PER_POSE;
            let t = self.t;
            let self_cal = followers_23(plan)?;
            let mut enc = [0; 4].map(|_| k * noise.encoder_mm * gauss(&mut self.rng));
            let mut covariates = Vec::with_capacity(3);
            if backlash.is_some() || lost_q4.is_some() {
                let dir = self.approach_direction(plan, self_cal, &mut approach)?;
                // the carrier lags its command against the direction of travel
                if let Some(m) = backlash {
                    enc[0] -= 0.5 * m * dir[0];
                    enc[3] -= 0.5 * m * dir[1];
                    covariates.extend([Some(dir[0]), Some(dir[1])]);
                }
                if let Some(b) = lost_q4 {
                    enc[3] -= b * dir[1];
                }
            }
            let st = self.machine_state(&plan.setup, plan.x, plan.y, t, enc, self_cal)?;
            let mut pose = self.drive_readings(plan, t, &st, (k, noise.encoder_mm), covariates);
            // the drive forces from the motor currents, with their noise
            for f in pose.f.iter_mut().filter(|f| **f != 0.0) {
                *f += k * noise.force_n * gauss(&mut self.force_rng);
            }
            pose.line = n + 2;
            self.read_relative(plan, (&st, t), (&noise, k), &mut zeroed, &mut pose)?;
            poses.push(pose);
        }
        Ok(self.campaign_of(source, poses, backlash.is_some()))
    }

    /// The campaign of measured `poses`: its comment names the twin's seed and effects, its
    /// covariates the temperature and, with backlash, the approach directions.
    fn campaign_of(&self, source: &str, poses: Vec<MeasuredPose>, backlash: bool) -> Campaign {
        let effects: Vec<String> = self
            .config
            .effects
            .iter()
            .map(|(e, m)| format!("{e}={m}"))
            .collect();
        let mut covariate_names = vec!["temp_machine".to_owned()];
        if self.config.thermal.guide_thermometers {
            covariate_names.extend(["temp_guide1", "temp_guide2"].map(str::to_owned));
        }
        if backlash {
            covariate_names.extend(["approach_q1", "approach_q4"].map(str::to_owned));
        }
        Campaign {
            source: source.to_owned(),
            comments: vec![format!(
                "rpkm digital twin: seed {}, effects [{}]",
                self.config.seed,
                effects.join(", ")
            )],
            covariate_names,
            poses,
        }
    }

    /// Measure the designs of `instruments` one after the other, in one campaign.
    pub fn campaign(&mut self, instruments: &[Instrument]) -> Result<Campaign, TwinError> {
        let (mut design, mut taken) = (Vec::new(), std::collections::HashSet::default());
        for &i in instruments {
            append_design(&mut design, &mut taken, design::for_instrument(i));
        }
        let names: Vec<&str> = instruments.iter().map(|i| i.as_str()).collect();
        self.run(&design, &names.join("+"))
    }

    /// Measure campaigns by name (`lt`, `kgm`, `dbb`, `li_x`, `li_y`, `li_psi`, `self`,
    /// `circle`); `validation` is [`Twin::validation`] with `n_validation` poses;
    /// `production` is [`PRODUCTION_POSES`] poses of [`design::production`], all drives
    /// active and no instrument (its drive forces need the `preload_elastic` effect).
    pub fn campaign_by_names(
        &mut self,
        names: &[&str],
        n_validation: usize,
    ) -> Result<Campaign, TwinError> {
        let (mut design, mut taken) = (Vec::new(), std::collections::HashSet::default());
        for n in names {
            if *n == "validation" {
                let more = self.validation_design(n_validation);
                append_design(&mut design, &mut taken, more);
                continue;
            }
            if *n == "production" {
                let more = design::production(PRODUCTION_POSES, self.config.seed ^ 0x9d0c);
                append_design(&mut design, &mut taken, more);
                continue;
            }
            let i: Instrument = n
                .parse()
                .ok()
                .filter(|i| *i != Instrument::None)
                .ok_or_else(|| TwinError::UnknownCampaign((*n).to_owned()))?;
            append_design(&mut design, &mut taken, design::for_instrument(i));
        }
        self.run(&design, &names.join("+"))
    }

    fn validation_design(&self, n: usize) -> Vec<PlannedPose> {
        design::validation(n, self.config.seed.wrapping_add(0x7a1d))
    }

    /// Held-out validation: `n` random poses measured with the laser tracker in one setup.
    pub fn validation(&mut self, n: usize) -> Result<Campaign, TwinError> {
        let d = self.validation_design(n);
        self.run(&d, "validation")
    }
}

/// Whether `plan` is measured with q2, q3 following (self-calibration always; another
/// instrument where its plan says so): the twin drives that mode or all four active.
fn followers_23(plan: &PlannedPose) -> Result<bool, TwinError> {
    if plan.instrument == Instrument::SelfCal || plan.follower == design::FOLLOWERS_23 {
        return Ok(true);
    }
    if plan.follower == [false; 4] {
        return Ok(false);
    }
    Err(TwinError::DriveMode {
        setup: plan.setup.clone(),
        follower: rpkm_core::campaign::followers_words(plan.follower),
    })
}

/// Poses of the `production` campaign of [`Twin::campaign_by_names`].
pub const PRODUCTION_POSES: usize = 500;

/// Appends `more` to `design`; a repeated campaign's setups get the repetition's number
/// (`lt`, then `lt_2`, ...): a setup is one mounting of the instrument with one reset, so
/// the same design measured again is a new setup (the spec allows one reset per setup).
fn append_design(
    design: &mut Vec<PlannedPose>,
    taken: &mut std::collections::HashSet<String>,
    mut more: Vec<PlannedPose>,
) {
    let name = |setup: &str, k: usize| {
        if k == 1 {
            setup.to_owned()
        } else {
            format!("{setup}_{k}")
        }
    };
    let mut k = 1;
    while more
        .iter()
        .any(|m| taken.contains(name(&m.setup, k).as_str()))
    {
        k += 1;
    }
    for p in &mut more {
        p.setup = name(&p.setup, k);
        taken.insert(p.setup.clone());
    }
    design.extend(more);
}

/// RMS (µm) of the instruments' own error in a campaign: its x, y readings against those of
/// the same twin measuring the same poses without noise (`clean`). On held-out poses, the
/// floor no model can go below.
pub fn reading_error_rms_um(noisy: &Campaign, clean: &Campaign) -> f64 {
    let e: Vec<f64> = noisy
        .poses
        .iter()
        .zip(&clean.poses)
        .filter(|(p, _)| !p.reset)
        .flat_map(|(p, q)| {
            [
                p.x.unwrap_or(0.0) - q.x.unwrap_or(0.0),
                p.y.unwrap_or(0.0) - q.y.unwrap_or(0.0),
            ]
        })
        .collect();
    1e3 * (e.iter().map(|v| v * v).sum::<f64>() / e.len().max(1) as f64).sqrt()
}
