//! Effects written as data: a name, parameters with their priors and, per changed input, an
//! expression of the pose's variables and the parameters ([`super::expr`]). They are fitted,
//! tested and reported like the library's; the command line reads them from a YAML file
//! (`--effects-file`, docs/effects.md), this module knows no file.
//!
//! What an expression may change ([`Target`]): a carrier position (`dq1`..`dq4`, carrier minus
//! encoder, mm), the recorded (x, y) of the 2-D instruments (`dx`, `dy`, true minus recorded,
//! mm), the recorded platform angle (`dpsi`, true minus recorded, rad) and any geometric
//! parameter at the pose (`dp.l3`, mm or rad). What it may read
//! ([`VARIABLES`]): the pose's carrier positions and forces, time, the derived covariates
//! (`dir_q4`, `travel_q4`, `t_run`), the campaign's `temp_*` and other covariate columns, the
//! nominal TCP (`x`, `y`), and a covariate's rate and lag along the campaign's time
//! (`rate(temp_machine)`, `lag(temp_machine, tau)`: [`super::memory`]).

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable};
use super::expr::{self, ExprError, Name, Program};
use super::memory::{self, Lagged, Timeline};
use crate::campaign::{Campaign, Instrument};
use crate::geometry;
use crate::params::{self, Model, Params};

/// The variables every campaign has (besides its covariate columns).
pub const VARIABLES: [&str; 20] = [
    "q1",
    "q2",
    "q3",
    "q4",
    "dir_q1",
    "dir_q2",
    "dir_q3",
    "dir_q4",
    "travel_q1",
    "travel_q2",
    "travel_q3",
    "travel_q4",
    "t",
    "t_run",
    "f1",
    "f2",
    "f3",
    "f4",
    "x",
    "y",
];

/// One parameter of a written effect.
#[derive(Clone, Debug, PartialEq)]
pub struct WrittenParam {
    pub name: String,
    pub unit: String,
    /// Prior σ, in `unit` (the parameter's scale in the fit).
    pub prior: f64,
    /// Plausible range, in `unit`: the expressions must be finite over it.
    pub bounds: Option<(f64, f64)>,
    /// Where the fit starts, in `unit` (0 unless written: a parameter the data do not move
    /// there, a time constant multiplying an amplitude that starts at 0, needs another).
    pub start: f64,
}

/// An input of the pose an expression changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Carrier `a` (0-based) minus its encoder, mm.
    Dq(usize),
    /// True minus recorded x of a 2-D instrument, mm.
    Dx,
    /// True minus recorded y, mm.
    Dy,
    /// True minus recorded platform angle (the angle interferometer's reading), rad.
    Dpsi,
    /// Geometric parameter `i` at the pose, mm or rad.
    Dp(usize),
}

impl Target {
    /// The target spelled `name` (`dq4`, `dx`, `dp.l3`; `dp.g1`/`dp.g2` for the γ angles).
    pub fn parse(name: &str) -> Option<Target> {
        if let Some(p) = name.strip_prefix("dp.") {
            let p = match p {
                "g1" => "gamma1",
                "g2" => "gamma2",
                other => other,
            };
            return params::index_of(p)
                .filter(|_| !p.is_empty())
                .map(Target::Dp);
        }
        match name {
            "dq1" => Some(Target::Dq(0)),
            "dq2" => Some(Target::Dq(1)),
            "dq3" => Some(Target::Dq(2)),
            "dq4" => Some(Target::Dq(3)),
            "dx" => Some(Target::Dx),
            "dy" => Some(Target::Dy),
            "dpsi" => Some(Target::Dpsi),
            _ => None,
        }
    }
}

/// An effect as written, before it is checked.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Spec {
    pub name: String,
    pub summary: String,
    pub params: Vec<WrittenParam>,
    /// (target as written, expression), in the file's order.
    pub targets: Vec<(String, String)>,
    /// The instruments `dx`, `dy` apply to (None: every 2-D one).
    pub instruments: Option<Vec<String>>,
}

/// What is wrong with a [`Spec`]; indices are into its lists.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SpecError {
    #[error("the name must be a word of letters, digits and `_`, found {0:?}")]
    Name(String),
    #[error("no expression: give at least one of dq1..dq4, dx, dy, dpsi, dp.NAME")]
    NoTarget,
    #[error(
        "unknown target `{name}`: expected dq1..dq4, dx, dy, dpsi or dp.NAME of the 29 parameters"
    )]
    UnknownTarget { target: usize, name: String },
    #[error("target `{name}` given twice")]
    DuplicateTarget { target: usize, name: String },
    #[error("{error}")]
    Expression { target: usize, error: ExprError },
    #[error("parameter `{name}`: {what}")]
    Param {
        param: usize,
        name: String,
        what: String,
    },
    #[error("unknown instrument `{name}`: expected one of lt, kgm, li_x, li_y")]
    Instrument { index: usize, name: String },
    #[error("`instruments` applies to dx and dy; this effect has neither")]
    InstrumentsWithoutDm,
}

/// A written effect, checked: its expressions parsed against its parameters and the
/// variables a campaign offers.
#[derive(Clone, Debug)]
pub struct Written {
    spec: Spec,
    targets: Vec<(Target, Program)>,
    /// The variables the expressions read, in the programs' `Name::Var` order.
    vars: Vec<String>,
    /// The lags the expressions read, in the programs' `Name::Lag` order.
    lags: Vec<LagSlot>,
    instruments: Vec<Instrument>,
}

/// One `lag(NAME, TAU)` of a written effect.
#[derive(Clone, Debug, PartialEq)]
pub struct LagSlot {
    /// The column lagged.
    pub column: String,
    /// Its time constant: parameter `k`, or seconds.
    pub tau: Result<usize, f64>,
}

/// Whether `name` is a word: letters, digits, `_`, not starting with a digit.
fn is_word(name: &str) -> bool {
    name.chars()
        .next()
        .is_some_and(|c| c.is_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_alphanumeric() || c == '_')
}

/// Whether `name` may be a variable: one of [`VARIABLES`], a `temp_*` column or one of the
/// campaign's covariate columns `columns`, or the rate of one (`rate(temp_machine)`).
fn is_variable(name: &str, columns: &[String]) -> bool {
    if let Some(inner) = name.strip_prefix("rate(").and_then(|n| n.strip_suffix(')')) {
        return is_column(inner, columns);
    }
    VARIABLES.contains(&name) || is_column(name, columns)
}

/// Whether `name` is a covariate column a campaign may have.
fn is_column(name: &str, columns: &[String]) -> bool {
    name.starts_with("temp_") || columns.iter().any(|c| c == name)
}

impl Written {
    /// Checks `spec`; `columns` are the covariate columns of the campaign it will meet, where
    /// known (names other than [`VARIABLES`] and `temp_*` are unknown otherwise).
    pub fn new(spec: Spec, columns: &[String]) -> Result<Written, SpecError> {
        if !is_word(&spec.name) {
            return Err(SpecError::Name(spec.name.clone()));
        }
        check_params(&spec.params, columns)?;
        if spec.targets.is_empty() {
            return Err(SpecError::NoTarget);
        }
        let vars = std::cell::RefCell::new(Vec::<String>::new());
        let lags = std::cell::RefCell::new(Vec::<LagSlot>::new());
        let resolve = |name: &str| {
            if let Some(k) = spec.params.iter().position(|p| p.name == name) {
                return Some(Name::Param(k));
            }
            if let Some(args) = name.strip_prefix("lag(").and_then(|n| n.strip_suffix(')')) {
                let (column, tau) = args.split_once(',')?;
                let param = spec.params.iter().position(|p| p.name == tau);
                let tau = match param {
                    Some(k) => Ok(k),
                    None => Err(tau.parse::<f64>().ok().filter(|v| v.is_finite())?),
                };
                if !is_column(column, columns) {
                    return None;
                }
                let slot = LagSlot {
                    column: column.to_owned(),
                    tau,
                };
                let mut lags = lags.borrow_mut();
                let k = lags.iter().position(|l| *l == slot).unwrap_or_else(|| {
                    lags.push(slot);
                    lags.len() - 1
                });
                return Some(Name::Lag {
                    slot: k,
                    tau: param,
                });
            }
            if !is_variable(name, columns) {
                return None;
            }
            let mut vars = vars.borrow_mut();
            let k = vars.iter().position(|v| v == name).unwrap_or_else(|| {
                vars.push(name.to_owned());
                vars.len() - 1
            });
            Some(Name::Var(k))
        };
        let mut targets: Vec<(Target, Program)> = Vec::new();
        for (k, (name, text)) in spec.targets.iter().enumerate() {
            let target = Target::parse(name).ok_or_else(|| SpecError::UnknownTarget {
                target: k,
                name: name.clone(),
            })?;
            if targets.iter().any(|t| t.0 == target) {
                return Err(SpecError::DuplicateTarget {
                    target: k,
                    name: name.clone(),
                });
            }
            let program = expr::parse(text, &resolve)
                .map_err(|error| SpecError::Expression { target: k, error })?;
            targets.push((target, program));
        }
        let instruments = instruments(&spec, &targets)?;
        Ok(Written {
            vars: vars.into_inner(),
            lags: lags.into_inner(),
            spec,
            targets,
            instruments,
        })
    }

    /// The effect as written.
    pub fn spec(&self) -> &Spec {
        &self.spec
    }

    /// Each parameter value set to test an expression's finiteness with: the starts (where a
    /// fit starts), each parameter at its start ± its prior and at its bounds.
    fn probes(&self) -> Vec<Vec<f64>> {
        let start: Vec<f64> = self.spec.params.iter().map(|p| p.start).collect();
        let mut out = vec![start.clone()];
        for (k, p) in self.spec.params.iter().enumerate() {
            let mut values = vec![p.start + p.prior, p.start - p.prior];
            if let Some((lo, hi)) = p.bounds {
                values.extend([lo, hi]);
            }
            for v in values {
                let mut theta = start.clone();
                theta[k] = v;
                out.push(theta);
            }
        }
        out
    }
}

fn check_params(params: &[WrittenParam], columns: &[String]) -> Result<(), SpecError> {
    for (k, p) in params.iter().enumerate() {
        let bad = |what: String| SpecError::Param {
            param: k,
            name: p.name.clone(),
            what,
        };
        if !is_word(&p.name) {
            return Err(bad(
                "the name must be a word of letters, digits and `_`".into()
            ));
        }
        if p.name == "pi"
            || expr::Func::ALL.iter().any(|f| f.0 == p.name)
            || is_variable(&p.name, columns)
        {
            return Err(bad("the name is a variable's or a function's".into()));
        }
        if params[..k].iter().any(|q| q.name == p.name) {
            return Err(bad("given twice".into()));
        }
        if !(p.prior.is_finite() && p.prior > 0.0) {
            return Err(bad(format!(
                "the prior must be a positive number, found {}",
                p.prior
            )));
        }
        if let Some((lo, hi)) = p.bounds {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(bad(format!(
                    "bounds [{lo}, {hi}]: expected two numbers, the lower first"
                )));
            }
            if !(lo..=hi).contains(&p.start) {
                return Err(bad(format!(
                    "start {} lies outside its bounds [{lo}, {hi}]",
                    p.start
                )));
            }
        }
        if !p.start.is_finite() {
            return Err(bad(format!("start {} is not a number", p.start)));
        }
    }
    Ok(())
}

fn instruments(spec: &Spec, targets: &[(Target, Program)]) -> Result<Vec<Instrument>, SpecError> {
    const TWO_D: [Instrument; 4] = [
        Instrument::Lt,
        Instrument::Kgm,
        Instrument::LiX,
        Instrument::LiY,
    ];
    let Some(names) = &spec.instruments else {
        return Ok(TWO_D.to_vec());
    };
    if !targets
        .iter()
        .any(|t| matches!(t.0, Target::Dx | Target::Dy))
    {
        return Err(SpecError::InstrumentsWithoutDm);
    }
    names
        .iter()
        .enumerate()
        .map(|(index, name)| {
            TWO_D
                .iter()
                .copied()
                .find(|i| i.as_str() == name)
                .ok_or_else(|| SpecError::Instrument {
                    index,
                    name: name.clone(),
                })
        })
        .collect()
}

/// An expression that is not finite at a pose: which target, at which line of the campaign.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{target} = {text:?} {what} at line {line} of {campaign}{at}")]
pub struct NotFinite {
    /// Index of the target in the spec.
    pub index: usize,
    pub target: String,
    pub text: String,
    /// What is not finite (`is NaN`, `has the derivative inf by `a``).
    pub what: String,
    pub line: usize,
    /// The campaign's source.
    pub campaign: String,
    /// The parameter values, where not all zero.
    pub at: String,
}

/// The variables of every pose, pose-major.
fn variables(campaign: &Campaign, names: &[String]) -> Result<Vec<Vec<f64>>, NotApplicable> {
    let n = campaign.poses.len();
    let mut columns: Vec<Vec<f64>> = Vec::with_capacity(names.len());
    let tcp = names
        .iter()
        .any(|v| v == "x" || v == "y")
        .then(|| nominal_tcp(campaign));
    for name in names {
        let column: Vec<f64> = match name.as_str() {
            "t" => campaign.poses.iter().map(|p| p.t).collect(),
            "x" | "y" => {
                let tcp = tcp.as_ref().map_or(&[][..], Vec::as_slice);
                tcp.iter()
                    .map(|c| if name == "x" { c.0 } else { c.1 })
                    .collect()
            }
            q if q.len() == 2 && (q.starts_with('q') || q.starts_with('f')) => {
                let a = usize::from(q.as_bytes()[1] - b'1');
                let f = q.starts_with('f');
                campaign
                    .poses
                    .iter()
                    .map(|p| if f { p.f[a] } else { p.q[a] })
                    .collect()
            }
            other => match other
                .strip_prefix("rate(")
                .and_then(|n| n.strip_suffix(')'))
            {
                Some(inner) => {
                    memory::rate(&timeline(campaign, other)?, &covariate(campaign, inner)?)
                }
                None => covariate(campaign, other)?,
            },
        };
        columns.push(column);
    }
    Ok((0..n)
        .map(|i| columns.iter().map(|c| c[i]).collect())
        .collect())
}

/// The campaign's rows in time order, for `what` (`rate(temp_machine)`) that needs them.
fn timeline(campaign: &Campaign, what: &str) -> Result<Timeline, NotApplicable> {
    let t: Vec<f64> = campaign.poses.iter().map(|p| p.t).collect();
    Timeline::new(&t).map_err(|e| NotApplicable {
        effect: String::new(),
        reason: format!("`{what}` {e} in {}", campaign.source),
    })
}

/// A covariate column with a value at every pose.
fn covariate(campaign: &Campaign, name: &str) -> Result<Vec<f64>, NotApplicable> {
    let column = super::effect::covariate_column(campaign, "", name)?;
    column
        .iter()
        .zip(&campaign.poses)
        .map(|(v, p)| {
            v.ok_or_else(|| NotApplicable {
                effect: String::new(),
                reason: format!(
                    "`{name}` has no value at line {} of {}",
                    p.line, campaign.source
                ),
            })
        })
        .collect()
}

/// Where each pose is: the nominal forward model of its (q1, q4), mm.
fn nominal_tcp(campaign: &Campaign) -> Vec<(f64, f64)> {
    let nominal = Params::nominal();
    campaign
        .poses
        .iter()
        .map(|p| nominal_xy(&nominal, &p.q))
        .collect()
}

impl Written {
    /// Binds the effect: its variables read at every pose and every expression checked
    /// finite there, value and derivatives, at the parameters of [`Written::probes`].
    pub fn bind_checked(&self, campaign: &Campaign) -> Result<BoundWritten, BindError> {
        let vars = variables(campaign, &self.vars).map_err(|e| {
            BindError::Variables(NotApplicable {
                effect: self.spec.name.clone(),
                reason: e.reason,
            })
        })?;
        let bound = BoundWritten {
            params: self
                .spec
                .params
                .iter()
                .map(|p| EffectParam {
                    name: p.name.clone(),
                    unit: p.unit.clone(),
                    prior: p.prior,
                    range: p.bounds,
                    start: p.start,
                    anchor: None,
                })
                .collect(),
            lags: self.lagged(campaign).map_err(BindError::Variables)?,
            targets: self.targets.clone(),
            applies: campaign
                .poses
                .iter()
                .map(|p| self.instruments.contains(&p.instrument))
                .collect(),
            vars,
        };
        self.check_finite(&bound, campaign)?;
        Ok(bound)
    }

    /// Each lag slot's column, ready to be evaluated at any time constant.
    fn lagged(&self, campaign: &Campaign) -> Result<Vec<LagColumn>, NotApplicable> {
        self.lags
            .iter()
            .map(|slot| {
                let what = format!("lag({}, ..)", slot.column);
                let bad = |e: NotApplicable| NotApplicable {
                    effect: self.spec.name.clone(),
                    reason: e.reason,
                };
                let line = timeline(campaign, &what).map_err(bad)?;
                let column = covariate(campaign, &slot.column).map_err(bad)?;
                Ok((Lagged::new(line, &column), slot.tau))
            })
            .collect()
    }

    fn check_finite(&self, bound: &BoundWritten, campaign: &Campaign) -> Result<(), BindError> {
        let mut stack = Vec::new();
        let mut grad = vec![0.0; bound.params.len()];
        let mut lags = Vec::new();
        for theta in self.probes() {
            for (i, pose) in campaign.poses.iter().enumerate() {
                bound.lag_values(i, &theta, &mut lags);
                for (index, (_, program)) in bound.targets.iter().enumerate() {
                    let v = program.eval((&bound.vars[i], &lags), &theta, &mut grad, &mut stack);
                    let what = if !v.is_finite() {
                        format!("is {v}")
                    } else if let Some(k) = grad.iter().position(|g| !g.is_finite()) {
                        format!(
                            "has the derivative {} by `{}`",
                            grad[k], self.spec.params[k].name
                        )
                    } else {
                        continue;
                    };
                    let (target, text) = self.spec.targets[index].clone();
                    return Err(BindError::NotFinite(Box::new(NotFinite {
                        index,
                        target,
                        text,
                        what,
                        line: pose.line,
                        campaign: campaign.source.clone(),
                        at: self.shown(&theta),
                    })));
                }
            }
        }
        Ok(())
    }

    /// ` with a = 0.1, c = 0` where the parameters are not all zero.
    fn shown(&self, theta: &[f64]) -> String {
        if theta.iter().all(|t| *t == 0.0) {
            return String::new();
        }
        let values: Vec<String> = self
            .spec
            .params
            .iter()
            .zip(theta)
            .map(|(p, t)| format!("{} = {t}", p.name))
            .collect();
        format!(" with {}", values.join(", "))
    }
}

/// Why a written effect cannot be bound to a campaign.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BindError {
    #[error(transparent)]
    Variables(NotApplicable),
    #[error(transparent)]
    NotFinite(Box<NotFinite>),
}

impl Effect for Written {
    fn name(&self) -> &str {
        &self.spec.name
    }
    fn summary(&self) -> &str {
        &self.spec.summary
    }
    fn has_memory(&self) -> bool {
        !self.lags.is_empty() || self.vars.iter().any(|v| v.starts_with("rate("))
    }
    fn bind(&self, campaign: &Campaign, _: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        match self.bind_checked(campaign) {
            Ok(b) => Ok(Box::new(b)),
            Err(BindError::Variables(e)) => Err(e),
            Err(BindError::NotFinite(e)) => Err(NotApplicable {
                effect: self.spec.name.clone(),
                reason: e.to_string(),
            }),
        }
    }
}

/// A written effect bound to a campaign.
pub struct BoundWritten {
    params: Vec<EffectParam>,
    targets: Vec<(Target, Program)>,
    /// Whether `dx`, `dy` apply at each pose (its instrument is one of the effect's).
    applies: Vec<bool>,
    /// Per pose, the values of the variables.
    vars: Vec<Vec<f64>>,
    /// Per lag slot, its column and time constant.
    lags: Vec<LagColumn>,
}

/// A lag slot's column, and its time constant (parameter `k`, or seconds).
type LagColumn = (Lagged, Result<usize, f64>);

impl BoundWritten {
    /// Each lag's value and derivative by its time constant at pose `pose` for `theta`.
    fn lag_values(&self, pose: usize, theta: &[f64], out: &mut Vec<(f64, f64)>) {
        out.clear();
        out.extend(self.lags.iter().map(|(lagged, tau)| {
            let tau = match *tau {
                Ok(k) => theta[k],
                Err(seconds) => seconds,
            };
            lagged.at(tau)[pose]
        }));
    }
}

impl Bound for BoundWritten {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        let mut stack = Vec::new();
        let mut grad = vec![0.0; theta.len()];
        let mut lags = Vec::new();
        self.lag_values(pose, theta, &mut lags);
        for (target, program) in &self.targets {
            if matches!(target, Target::Dx | Target::Dy) && !self.applies[pose] {
                continue;
            }
            let v = program.eval((&self.vars[pose], &lags), theta, &mut grad, &mut stack);
            add(value, *target, v);
            for (d, g) in partials.iter_mut().zip(&grad) {
                add(d, *target, *g);
            }
        }
    }
}

pub(super) fn add(d: &mut Delta, target: Target, v: f64) {
    match target {
        Target::Dq(a) => d.dq[a] += v,
        Target::Dx => d.dm.x += v,
        Target::Dy => d.dm.y += v,
        Target::Dpsi => d.dpsi += v,
        Target::Dp(i) => d.dp[i] += v,
    }
}

impl Written {
    /// The variables the expressions read.
    pub fn variables(&self) -> &[String] {
        &self.vars
    }

    /// The lags the expressions read (`lag(NAME, TAU)`).
    pub fn lags(&self) -> &[LagSlot] {
        &self.lags
    }

    /// Each target with its expression, in the spec's order (the programs read the
    /// variables in [`Written::variables`] order).
    pub(super) fn programs(&self) -> &[(Target, Program)] {
        &self.targets
    }
}

/// The nominal forward model of the carriers `q` (mm), NaN where it cannot be solved (an
/// expression of `x`, `y` is then not finite there).
pub(super) fn nominal_xy(nominal: &Params, q: &[f64; 4]) -> (f64, f64) {
    geometry::fgm(nominal, Model::M29, q[0], q[3]).map_or((f64::NAN, f64::NAN), |s| (s.x(), s.y()))
}
