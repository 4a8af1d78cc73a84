//! The twin at work: a production stream (issue 15). A machining-like path (straight contour
//! moves at feed speed between random targets over the workspace), all four drives
//! position-controlled, the drive forces with the stream's own noise, a machine temperature
//! that drifts (its own law: a ramp with a cycling ripple, which no model here assumes) and
//! optionally a crash that bends a rod (a step in its length at a given time). Every sample
//! carries the truth beside the readings: the true parameters at that time (thermal expansion
//! and step included) and the true TCP.

use super::machine::{gauss, Twin, TwinError, TEMP_SENSOR_K};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rpkm_core::design::{X_RANGE, Y_RANGE};
use rpkm_core::elastic::{self, Equilibrium, ALL_ACTIVE};
use rpkm_core::geometry;
use rpkm_core::params::{Model, Params};

/// A step change of one parameter (a crash that bends a rod).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepChange {
    /// Stream time of the crash, s.
    pub at_s: f64,
    /// Parameter index (a rod length l1..l5).
    pub param: usize,
    /// Change, mm (rad for an angle).
    pub change: f64,
}

/// A parameter that creeps with the machine temperature beyond the thermal expansion (a
/// clamping that slips as the frame warms, a guide that bends): its change from the start
/// is `per_k` times the temperature's.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Creep {
    /// Parameter index.
    pub param: usize,
    /// mm (rad for an angle) per K.
    pub per_k: f64,
}

/// A parameter that creeps over time, whatever the temperature (a clamping that slips under
/// the machining loads, a joint that wears): from `from_s` it moves at a steady rate by
/// `change` over `over_s`, then holds.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimeCreep {
    /// Parameter index.
    pub param: usize,
    /// Stream time the creep starts, s.
    pub from_s: f64,
    /// How long it creeps, s.
    pub over_s: f64,
    /// Its whole change, mm (rad for an angle).
    pub change: f64,
}

impl TimeCreep {
    /// The creep's change at stream time `t`.
    pub fn at(&self, t: f64) -> f64 {
        let f = if self.over_s > 0.0 {
            ((t - self.from_s) / self.over_s).clamp(0.0, 1.0)
        } else {
            f64::from(u8::from(t >= self.from_s))
        };
        self.change * f
    }
}

/// A motion the cell commands in the middle of production: from `at_s` the path heads for
/// each pose in turn at feed speed, stays at each `dwell_s`, then goes on with its contour
/// moves (the motion the online tracker asks for to tell a tie apart).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Visit {
    /// Stream time the cell commands the motion, s.
    pub at_s: f64,
    /// The poses (x, y mm), in order.
    pub poses: Vec<(f64, f64)>,
    /// How long the machine stays at each, s.
    pub dwell_s: f64,
}

/// What the production stream does.
#[derive(Clone, Debug, PartialEq)]
pub struct ProductionConfig {
    /// Sample rate of the drive interface, Hz.
    pub rate_hz: f64,
    /// Length of the stream, s.
    pub seconds: f64,
    /// Feed speed of the contour moves, mm/s.
    pub feed_mm_s: f64,
    /// Machine temperature at the start, °C.
    pub start_temp_c: f64,
    /// Temperature drift, K per hour.
    pub drift_k_per_h: f64,
    /// Amplitude of the temperature's cycling ripple (period [`RIPPLE_PERIOD_S`]), K.
    pub ripple_k: f64,
    /// σ of the drive forces read from the motor currents, N (the stream's own).
    pub force_noise_n: f64,
    pub step: Option<StepChange>,
    pub creep: Option<Creep>,
    pub time_creep: Option<TimeCreep>,
    pub visit: Option<Visit>,
    /// Seed of the path and the noise.
    pub seed: u64,
}

/// Period of the temperature ripple, s (coolant cycling).
pub const RIPPLE_PERIOD_S: f64 = 900.0;

impl Default for ProductionConfig {
    fn default() -> Self {
        ProductionConfig {
            rate_hz: 1000.0,
            seconds: 3600.0,
            feed_mm_s: 50.0,
            start_temp_c: 20.0,
            drift_k_per_h: 4.0,
            ripple_k: 0.2,
            force_noise_n: 3.0,
            step: None,
            creep: None,
            time_creep: None,
            visit: None,
            seed: 1,
        }
    }
}

impl ProductionConfig {
    /// The true machine temperature at stream time `t`, °C.
    pub fn temperature(&self, t: f64) -> f64 {
        self.start_temp_c
            + self.drift_k_per_h * t / 3600.0
            + self.ripple_k * (2.0 * std::f64::consts::PI * t / RIPPLE_PERIOD_S).sin()
    }

    /// Number of samples.
    pub fn samples(&self) -> usize {
        rpkm_core::convert::round_count(self.seconds * self.rate_hz)
    }
}

/// One sample of the production stream: the readings and the truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProductionSample {
    /// Stream time, s.
    pub t: f64,
    /// Drive positions (the commands the drives hold), mm.
    pub q: [f64; 4],
    /// Drive forces from the motor currents, with noise, N.
    pub f: [f64; 4],
    /// The machine thermometer, °C.
    pub temp_c: f64,
    /// Truth: the machine's parameters now (thermal expansion and any step included).
    pub truth: Params,
    /// Truth: the TCP (x, y mm, ψ rad).
    pub tcp: [f64; 3],
    /// Truth: the drive forces without noise, N.
    pub f_true: [f64; 4],
}

/// The production stream of a twin (an iterator of samples).
pub struct ProductionStream<'a> {
    twin: &'a Twin,
    cfg: ProductionConfig,
    controller: Params,
    path_rng: StdRng,
    noise_rng: StdRng,
    k: usize,
    at: (f64, f64),
    target: (f64, f64),
    warm: Option<Equilibrium>,
    encoder_mm: f64,
    /// Where the commanded visit stands.
    visit: VisitState,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum VisitState {
    Pending,
    /// Heading for the pose of this index.
    Going(usize),
    /// At the pose of this index until this stream time.
    Dwelling(usize, f64),
    Done,
}

impl<'a> ProductionStream<'a> {
    /// The stream of `twin` (its true machine, stiffness, controller and encoder noise) under
    /// `cfg`. The twin's thermal physics says what expands; its temperature law is replaced by
    /// the stream's.
    pub fn new(twin: &'a Twin, cfg: ProductionConfig) -> ProductionStream<'a> {
        let mut path_rng = StdRng::seed_from_u64(cfg.seed ^ 0x9a7e_0000_0000_0015);
        let at = random_target(&mut path_rng);
        let target = random_target(&mut path_rng);
        ProductionStream {
            controller: twin.controller(false),
            noise_rng: StdRng::seed_from_u64(cfg.seed ^ 0x9015_e000_0000_0015),
            encoder_mm: twin.config().noise.as_ref().map_or(0.0, |n| n.encoder_mm),
            twin,
            cfg,
            path_rng,
            k: 0,
            at,
            target,
            warm: None,
            visit: VisitState::Pending,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ProductionConfig {
        &self.cfg
    }

    /// The true parameters at time `t` with guide-2 carriers at s1, s4.
    fn truth_at(&self, t: f64, s1: f64, s4: f64) -> Params {
        let mut p = self.twin.effective(self.cfg.temperature(t), s1, s4);
        if let Some(step) = self.cfg.step.filter(|s| t >= s.at_s) {
            p[step.param] += step.change;
        }
        if let Some(c) = self.cfg.creep {
            p[c.param] += c.per_k * (self.cfg.temperature(t) - self.cfg.start_temp_c);
        }
        if let Some(c) = self.cfg.time_creep {
            p[c.param] += c.at(t);
        }
        p
    }

    /// Where the path goes from stream time `t`: a commanded visit overrides the contour.
    fn steer(&mut self, t: f64) {
        let Some(v) = &self.cfg.visit else { return };
        let (at_s, dwell_s) = (v.at_s, v.dwell_s);
        let arrived = |i: usize| v.poses.get(i) == Some(&self.at);
        self.visit = match self.visit {
            VisitState::Pending if t >= at_s => self.head_for(0),
            VisitState::Going(i) if arrived(i) => VisitState::Dwelling(i, t + dwell_s),
            VisitState::Dwelling(i, until) if t >= until => self.head_for(i + 1),
            state => state,
        };
    }

    /// Heads for the visit's pose `i`, or back to the contour moves after its last.
    fn head_for(&mut self, i: usize) -> VisitState {
        let pose = self
            .cfg
            .visit
            .as_ref()
            .and_then(|v| v.poses.get(i).copied());
        if let Some(pose) = pose {
            self.target = pose;
            VisitState::Going(i)
        } else {
            self.target = random_target(&mut self.path_rng);
            VisitState::Done
        }
    }

    /// Moves the TCP one sample along the path.
    fn advance(&mut self) {
        self.steer(self.k as f64 / self.cfg.rate_hz);
        if matches!(self.visit, VisitState::Dwelling(..)) {
            return;
        }
        let ds = self.cfg.feed_mm_s / self.cfg.rate_hz;
        let (dx, dy) = (self.target.0 - self.at.0, self.target.1 - self.at.1);
        let d = dx.hypot(dy);
        if d <= ds {
            self.at = self.target;
            self.target = random_target(&mut self.path_rng);
        } else {
            self.at = (self.at.0 + dx / d * ds, self.at.1 + dy / d * ds);
        }
    }

    fn sample(&mut self) -> Result<ProductionSample, TwinError> {
        let t = self.k as f64 / self.cfg.rate_hz;
        let (x, y) = self.at;
        let cmd = geometry::igm(&self.controller, Model::M29, x, y)
            .map_err(|source| TwinError::Controller {
                setup: "production".to_owned(),
                x,
                y,
                source,
            })?
            .q();
        let temp = self.cfg.temperature(t);
        let sc = self.twin.scale(temp);
        let s =
            [0, 1, 2, 3].map(|a| (cmd[a] + self.encoder_mm * gauss(&mut self.noise_rng)) * sc[a]);
        let truth = self.truth_at(t, s[0], s[3]);
        let k = self.twin.stiffness();
        let solved = match &self.warm {
            Some(w) => elastic::fegm_from(&truth, &k, s, ALL_ACTIVE, w),
            None => elastic::fegm(&truth, &k, s, ALL_ACTIVE),
        };
        let eq = solved.map_err(|source| TwinError::Elastic {
            setup: "production".to_owned(),
            x,
            y,
            source,
        })?;
        self.warm = Some(eq);
        let mut f = eq.drive_force;
        for v in &mut f {
            *v += self.cfg.force_noise_n * gauss(&mut self.noise_rng);
        }
        Ok(ProductionSample {
            t,
            q: cmd,
            f,
            temp_c: temp + TEMP_SENSOR_K * gauss(&mut self.noise_rng),
            truth,
            tcp: [eq.x, eq.y, eq.psi],
            f_true: eq.drive_force,
        })
    }
}

fn random_target(rng: &mut StdRng) -> (f64, f64) {
    (
        rng.gen_range(X_RANGE.0..=X_RANGE.1),
        rng.gen_range(Y_RANGE.0..=Y_RANGE.1),
    )
}

impl Iterator for ProductionStream<'_> {
    type Item = Result<ProductionSample, TwinError>;
    fn next(&mut self) -> Option<Self::Item> {
        if self.k >= self.cfg.samples() {
            return None;
        }
        let out = self.sample();
        self.advance();
        self.k += 1;
        Some(out)
    }
}
