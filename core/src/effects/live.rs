//! Written effects at calibrated values, applied to a live stream of drive states (the TCP
//! estimator, the preload monitor): each state's carrier positions (`dq`) and geometric
//! parameters (`dp`) change as the campaign's poses changed in the fit. The instruments'
//! corrections (`dx`, `dy`, `dpsi`) are left out: a drive state has no instrument reading.
//!
//! An expression reads live what a drive state has: `q1`..`q4`, `f1`..`f4`, `t`, the
//! stream's `dir_q1`.., `travel_q1`.., `t_run` (a [`crate::campaign::Motion`] along the
//! stream: the definition the campaign's derived covariates use) and the nominal TCP `x`,
//! `y`. An effect that reads anything else (a temperature column) is refused when it is
//! applied ([`LiveError::NotLive`]), never evaluated with a made-up value.
//!
//! Per state nothing is allocated once the first has been evaluated: the variables are
//! resolved when the effects are applied, the evaluation's buffers kept.

use super::effect::Delta;
use super::expr::Program;
use super::written::{self, Target, Written};
use crate::campaign::MotionCovariates;
use crate::params::{Params, N_PARAMS};

/// What an expression may read of one drive state of a stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiveState {
    /// Encoder readings, mm.
    pub q: [f64; 4],
    /// Drive forces, N.
    pub f: [f64; 4],
    /// Time, s.
    pub t: f64,
    /// How the carriers moved to this state along the stream.
    pub motion: MotionCovariates,
}

/// Where a variable's value comes from in a [`LiveState`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Source {
    Q(usize),
    F(usize),
    T,
    TRun,
    Dir(usize),
    Travel(usize),
    X,
    Y,
}

/// The variables a live state has, as the error names them.
const LIVE: &str = "q1..q4, f1..f4, t, t_run, dir_q1..dir_q4, travel_q1..travel_q4, x, y";

impl Source {
    fn of(name: &str) -> Option<Source> {
        let carrier = |n: &str| match n {
            "1" => Some(0),
            "2" => Some(1),
            "3" => Some(2),
            "4" => Some(3),
            _ => None,
        };
        if let Some(n) = name.strip_prefix("dir_q") {
            return carrier(n).map(Source::Dir);
        }
        if let Some(n) = name.strip_prefix("travel_q") {
            return carrier(n).map(Source::Travel);
        }
        if let Some(n) = name.strip_prefix('q') {
            return carrier(n).map(Source::Q);
        }
        if let Some(n) = name.strip_prefix('f') {
            return carrier(n).map(Source::F);
        }
        match name {
            "t" => Some(Source::T),
            "t_run" => Some(Source::TRun),
            "x" => Some(Source::X),
            "y" => Some(Source::Y),
            _ => None,
        }
    }

    fn value(self, s: &LiveState, xy: (f64, f64)) -> f64 {
        match self {
            Source::Q(a) => s.q[a],
            Source::F(a) => s.f[a],
            Source::T => s.t,
            Source::TRun => s.motion.t_run,
            Source::Dir(a) => s.motion.dir[a],
            Source::Travel(a) => s.motion.travel[a],
            Source::X => xy.0,
            Source::Y => xy.1,
        }
    }
}

/// Why written effects cannot be applied to a live stream.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LiveError {
    #[error(
        "effect `{effect}` reads `{variable}`, which a drive state does not have (it has {LIVE})"
    )]
    NotLive { effect: String, variable: String },
    #[error("effect `{effect}` has {expected} parameters, {found} values given")]
    Values {
        effect: String,
        expected: usize,
        found: usize,
    },
}

/// One effect with its values.
#[derive(Clone, Debug)]
struct Applied {
    name: String,
    programs: Vec<(Target, Program)>,
    sources: Vec<Source>,
    theta: Vec<f64>,
}

/// Buffers of the evaluation, kept from state to state.
#[derive(Clone, Debug, Default)]
struct Scratch {
    vars: Vec<f64>,
    grad: Vec<f64>,
    stack: Vec<f64>,
}

/// Written effects at calibrated values (θ in each parameter's unit), applied to live
/// drive states.
#[derive(Clone, Debug, Default)]
pub struct LiveEffects {
    applied: Vec<Applied>,
    /// Whether an expression reads the nominal TCP (one forward solve per state).
    reads_tcp: bool,
    nominal: Params,
    scratch: Scratch,
}

impl LiveEffects {
    /// The effects `effects`, each with its parameter values (in the order of its spec's
    /// parameters, in their units).
    pub fn new(effects: &[(&Written, Vec<f64>)]) -> Result<LiveEffects, LiveError> {
        let mut applied = Vec::with_capacity(effects.len());
        for (w, theta) in effects {
            let name = w.spec().name.clone();
            let expected = w.spec().params.len();
            if theta.len() != expected {
                return Err(LiveError::Values {
                    effect: name,
                    expected,
                    found: theta.len(),
                });
            }
            if let Some(lag) = w.lags().first() {
                return Err(LiveError::NotLive {
                    effect: name,
                    variable: format!("lag({}, ..)", lag.column),
                });
            }
            let sources = w
                .variables()
                .iter()
                .map(|v| {
                    Source::of(v).ok_or_else(|| LiveError::NotLive {
                        effect: name.clone(),
                        variable: v.clone(),
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
            applied.push(Applied {
                name,
                programs: w.programs().to_vec(),
                sources,
                theta: theta.clone(),
            });
        }
        let reads_tcp = applied
            .iter()
            .any(|a| a.sources.iter().any(|s| matches!(s, Source::X | Source::Y)));
        Ok(LiveEffects {
            applied,
            reads_tcp,
            nominal: Params::nominal(),
            scratch: Scratch::default(),
        })
    }

    /// Whether no effect is applied.
    pub fn is_empty(&self) -> bool {
        self.applied.is_empty()
    }

    /// The effects' names and values, in order.
    pub fn values(&self) -> impl Iterator<Item = (&str, &[f64])> {
        self.applied.iter().map(|a| (a.name.as_str(), &a.theta[..]))
    }

    /// The first effect that reads a drive force `f` lacks (NaN: not measured, a cell
    /// without force sensing), with the drive 0..=3: such a state cannot be evaluated under
    /// the effects, and no value is made up for the force.
    pub fn unmeasured_force(&self, f: &[f64; 4]) -> Option<(&str, usize)> {
        self.applied.iter().find_map(|a| {
            a.sources.iter().find_map(|s| match s {
                Source::F(d) if f[*d].is_nan() => Some((a.name.as_str(), *d)),
                _ => None,
            })
        })
    }

    /// The change of state `s`'s inputs (its carriers and parameters; no instrument).
    pub fn delta(&mut self, s: &LiveState) -> Delta {
        let mut out = Delta::default();
        if self.applied.is_empty() {
            return out;
        }
        let xy = if self.reads_tcp {
            written::nominal_xy(&self.nominal, &s.q)
        } else {
            (f64::NAN, f64::NAN)
        };
        let sc = &mut self.scratch;
        for a in &self.applied {
            sc.vars.clear();
            sc.vars.extend(a.sources.iter().map(|v| v.value(s, xy)));
            sc.grad.clear();
            sc.grad.resize(a.theta.len(), 0.0);
            for (target, program) in &a.programs {
                if matches!(target, Target::Dx | Target::Dy | Target::Dpsi) {
                    continue;
                }
                let v = program.eval((&sc.vars, &[]), &a.theta, &mut sc.grad, &mut sc.stack);
                written::add(&mut out, *target, v);
            }
        }
        out
    }

    /// The parameters and carrier positions (mm) the model is evaluated at for state `s`
    /// under the effects at geometry `p`: `p + dp`, `q + dq`.
    pub fn apply(&mut self, p: &Params, s: &LiveState) -> (Params, [f64; 4]) {
        if self.applied.is_empty() {
            return (*p, s.q);
        }
        let d = self.delta(s);
        let mut pc = *p;
        for k in 0..N_PARAMS {
            pc[k] += d.dp[k];
        }
        (pc, [0, 1, 2, 3].map(|a| s.q[a] + d.dq[a]))
    }
}
