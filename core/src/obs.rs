//! Model values of the measurements (thesis 4.2.1.1 and 4.3.1): for each pose of a campaign
//! the rows the calibration compares, W_mod − W_meas, with their analytic Jacobian rows.
//!
//! - Laser tracker, grid encoder (inverse calibration, eq. 4.30): Q = igm(X_meas + fgm(Q_nr,reset, P), P),
//!   compared with all four recorded actuator positions.
//! - Ball-bar (eq. 4.31), interferometer x/y, platform angle (forward calibration): the distance
//!   to the pivot, the coordinate or ψ relative to the reset pose, through each of the
//!   non-redundant subsystems (q1, q4) and (q3, q4) ("multiple use of the same data").
//! - Their second step (eq. 4.32): q2 = igm(X_e, P) from virtual measurements X_e = fgm(Q_nr, P_cal).
//! - Self-calibration (eq. 4.37): (q2, q3) = rgm(q1, q4, P) against the follower encoders.
//!
//! Each row carries its own standard deviation: the instrument noise of `noise` propagated
//! through the model's local derivatives (task-variable scaling, eq. 3.22).
//!
//! Physical effects ([`crate::effects`]) enter as per-pose corrections of the model's inputs
//! (parameters, carrier positions, recorded x/y); each row keeps its sensitivity to those
//! inputs so that the Jacobian over the effects' parameters is one chain rule
//! ([`Corrections::theta_row`]).

use crate::campaign::{Campaign, Instrument, Pose};
use crate::effects::{Corrections, Delta, InputSensitivity};
use crate::elastic::{fegm, fegm_from, ElasticError, Equilibrium, Stiffness, ALL_ACTIVE};
use crate::geometry::{self, q_var, GeometryError, Solution, Subsystem, PSI, X, Y};
use crate::noise::{self, ForceModes, NoiseModel, Parts, XyInstrument};
use crate::params::{Model, Params, D1, D2, GAMMA1, GAMMA2, N_PARAMS};
use nalgebra::{Matrix4, Vector2};

pub use crate::params::Row;

/// What a row measures: the instrument's direction and, for forward rows, the subsystem used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Direction {
    /// Actuator position q1..q4 (index 0..=3) from the inverse model or rgm.
    Q(usize),
    /// Ball-bar distance through the subsystem (q_a, q_b).
    R(usize, usize),
    /// x coordinate through (q_a, q_b).
    X(usize, usize),
    /// y coordinate through (q_a, q_b).
    Y(usize, usize),
    /// platform angle through (q_a, q_b).
    Psi(usize, usize),
    /// q2 from the virtual measurements of the forward step (second step).
    VirtualQ2,
    /// A 2-D instrument's four q rows of one pose, decorrelated ([`decorrelate`]): the TCP
    /// misfit along and across the tracker's beam (x and y for the grid encoder), mm ...
    Along,
    Across,
    /// ... and the two combinations of the four drives the TCP cannot move: the
    /// incompatibility of the recorded drives, which only encoder noise and the geometry set.
    Compat(usize),
    /// Drive force f1..f4 (index 0..=3, N) with all four drives position-controlled: the
    /// model's preload at the recorded positions minus the recorded force.
    F(usize),
    /// The four force rows of a pose decorrelated ([`decorrelate_forces`]): their
    /// combinations along [`ForceModes`], largest encoder share first (N): the preload
    /// modes the drives' position noise enters (two), then those it does not.
    FMode(usize),
}

impl std::fmt::Display for Direction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Direction::Q(i) => write!(f, "q{}", i + 1),
            Direction::R(a, b) => write!(f, "r(q{},q{})", a + 1, b + 1),
            Direction::X(a, b) => write!(f, "x(q{},q{})", a + 1, b + 1),
            Direction::Y(a, b) => write!(f, "y(q{},q{})", a + 1, b + 1),
            Direction::Psi(a, b) => write!(f, "psi(q{},q{})", a + 1, b + 1),
            Direction::VirtualQ2 => write!(f, "q2 (virtual)"),
            Direction::Along => write!(f, "along"),
            Direction::Across => write!(f, "across"),
            Direction::Compat(k) => write!(f, "compat{}", k + 1),
            Direction::F(a) => write!(f, "f{}", a + 1),
            Direction::FMode(k) => write!(f, "fmode{}", k + 1),
        }
    }
}

impl Direction {
    /// Unit of the row's residual: mm, or rad for ψ (or N for a force: see [`Self::is_force`]).
    pub fn is_angle(self) -> bool {
        matches!(self, Direction::Psi(..))
    }

    /// Whether the row's residual is a drive force (N).
    pub fn is_force(self) -> bool {
        matches!(self, Direction::F(..) | Direction::FMode(..))
    }

    /// Whether the row's residual is a length (mm).
    pub fn is_length(self) -> bool {
        !self.is_angle() && !self.is_force()
    }

    /// How a residual of this direction is reported: the factor from its unit (mm, rad, N)
    /// and the reported unit.
    pub fn report_unit(self) -> (f64, &'static str) {
        if self.is_angle() {
            (1e6, "µrad")
        } else if self.is_force() {
            (1.0, "N")
        } else {
            (1e3, "µm")
        }
    }
}

/// One compared value.
#[derive(Clone, Debug)]
pub struct Residual {
    /// Index of the pose in the campaign.
    pub pose: usize,
    pub instrument: Instrument,
    pub direction: Direction,
    /// W_mod − W_meas (mm or rad).
    pub value: f64,
    /// Standard deviation of the row (mm or rad): its weight is 1/sigma.
    pub sigma: f64,
    /// Its variance (sigma²) split by noise group, to estimate each group's level.
    pub parts: Parts,
    /// d value / d p over the 29 parameters.
    pub jacobian: Row,
    /// For virtual rows of the second step: d value / d p_cal, the sensitivity to the
    /// first step's parameters that made the virtual measurement (to propagate their
    /// uncertainty); None for measured rows (boxed: most rows are measured, and a large
    /// campaign keeps its rows).
    pub d_pcal: Option<Box<Row>>,
    /// d value / d θ over the effects' parameters (empty without effects; zero for the
    /// virtual rows of the second step, which hold the effects fixed).
    pub d_theta: Vec<f64>,
    /// The row's gains on the errors its setup's reset pose puts into every row of the
    /// setup ([`ResetGain`], [`share_reset`]); zero where the row reads no reset pose.
    pub reset_gain: ResetGain,
}

/// A row's gains on what its setup's reset pose read once for all its rows: the error of the
/// reading the instrument was zeroed on (x, y of a 2-D instrument; a single coordinate or ψ
/// in the first), then the errors of the reset pose's four encoders (the model adds the reset
/// pose's TCP, or subtracts its configuration, from every reading).
pub type ResetGain = nalgebra::SVector<f64, 6>;

/// The [`ResetGain`] of a row: `reading` on the instrument's zero, `reset` the row's
/// sensitivity to the reset pose's carrier positions.
fn reset_gain(reading: Vector2<f64>, reset: &[f64; 4]) -> ResetGain {
    ResetGain::from_column_slice(&[reading.x, reading.y, reset[0], reset[1], reset[2], reset[3]])
}

/// A row's value without its derivatives: what a fit keeps of its rows (the statistics,
/// the noise estimation and the diagnosis read these; a campaign of 10⁵ poses keeps them in
/// a fifth of the memory of its [`Residual`]s).
#[derive(Clone, Debug)]
pub struct RowValue {
    pub pose: usize,
    pub instrument: Instrument,
    pub direction: Direction,
    /// W_mod − W_meas (mm or rad).
    pub value: f64,
    /// Standard deviation of the row (mm or rad).
    pub sigma: f64,
    /// Its variance split by noise group.
    pub parts: Parts,
}

impl From<&Residual> for RowValue {
    fn from(r: &Residual) -> RowValue {
        RowValue {
            pose: r.pose,
            instrument: r.instrument,
            direction: r.direction,
            value: r.value,
            sigma: r.sigma,
            parts: r.parts,
        }
    }
}

/// A pose the model could not evaluate, with its source line.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{source}:{line}: {instrument} pose: {error}")]
pub struct PoseError {
    pub source: String,
    pub line: usize,
    pub instrument: &'static str,
    #[source]
    pub error: ModelError,
}

/// Why the model could not evaluate a pose: its geometry, or (for a drive-force row) the
/// elastic equilibrium.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    #[error(transparent)]
    Elastic(#[from] ElasticError),
}

impl PoseError {
    /// The error `error` of `pose` in `campaign`, located by its file and line.
    pub fn at(campaign: &Campaign, pose: &Pose, error: impl Into<ModelError>) -> PoseError {
        PoseError {
            source: campaign.source.clone(),
            line: pose.line,
            instrument: pose.instrument.as_str(),
            error: error.into(),
        }
    }
}

/// The forward subsystems used by forward calibration rows (thesis 4.2.1).
pub const FORWARD_SUBSYSTEMS: [Subsystem; 2] =
    [Subsystem::Actuators(0, 3), Subsystem::Actuators(2, 3)];

/// A solved forward model with its parameter and actuator sensitivities.
struct Forward {
    sol: Solution,
    sens: geometry::Sensitivity,
}

impl Forward {
    fn zeros() -> Forward {
        Forward {
            sol: Solution {
                c: geometry::Config::zeros(),
                iterations: 0,
                residual: 0.0,
            },
            sens: geometry::Sensitivity::zeros(),
        }
    }
}

fn forward(
    p: &Params,
    model: Model,
    sub: Subsystem,
    q: &[f64; 4],
) -> Result<Forward, GeometryError> {
    let mut f = Forward {
        sol: solve_forward(p, model, sub, q)?,
        sens: geometry::Sensitivity::zeros(),
    };
    geometry::sensitivity_into(p, model, sub, &f.sol, &mut f.sens)?;
    Ok(f)
}

/// The configuration of a forward subsystem `sub` at the actuator positions `q`.
fn solve_forward(
    p: &Params,
    model: Model,
    sub: Subsystem,
    q: &[f64; 4],
) -> Result<Solution, GeometryError> {
    let Subsystem::Actuators(a, b) = sub else {
        unreachable!("forward rows use actuator subsystems")
    };
    geometry::solve(p, model, sub, [q[a], q[b]])
}

/// Parameters and carrier positions of a pose under its effect correction.
fn corrected(p: &Params, q: &[f64; 4], d: &Delta) -> (Params, [f64; 4]) {
    let mut pc = *p;
    for k in 0..N_PARAMS {
        pc[k] += d.dp[k];
    }
    (pc, [0, 1, 2, 3].map(|a| q[a] + d.dq[a]))
}

/// Sensitivity to the pose's inputs of Σ g_v · c_v of a forward solve through `sub`.
fn input_sensitivity(f: &Forward, sub: Subsystem, g: &[(usize, f64)]) -> InputSensitivity {
    let mut s = InputSensitivity::default();
    let Subsystem::Actuators(a, b) = sub else {
        return s;
    };
    for &(v, w) in g {
        s.dp += f.sens.dc_dp.row(v).transpose() * w;
        s.dq[a] += f.sens.dc_dk[(v, 0)] * w;
        s.dq[b] += f.sens.dc_dk[(v, 1)] * w;
    }
    s
}

/// The same sensitivity with the opposite sign (the reset pose of a relative value).
fn negated(mut s: InputSensitivity) -> InputSensitivity {
    s.dp = -s.dp;
    s.dq = s.dq.map(|v| -v);
    s.dm = -s.dm;
    s.dpsi = -s.dpsi;
    s.dk = -s.dk;
    s
}

/// Squared gain from the known actuators' encoders to configuration variable `v`.
fn encoder_gain2(f: &Forward, v: usize) -> f64 {
    f.sens.dc_dk[(v, 0)].powi(2) + f.sens.dc_dk[(v, 1)].powi(2)
}

/// Which kinds of rows to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Direct rows of every instrument (inverse, forward, self-calibration).
    Direct,
    /// Second step of forward instruments: q2 from virtual measurements made with `p_cal`.
    VirtualQ2,
}

/// Rows of one campaign under parameters `p`. Reset poses of relative instruments give no
/// row of their own (their measured value is zero by definition); `circle` and `none` poses
/// give none (the circular test is an evaluation, not a calibration measurement).
pub fn residuals(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PoseError> {
    residuals_in(
        campaign,
        p,
        model,
        step,
        p_cal,
        &Corrections::default(),
        noise,
        Form::Thesis,
    )
}

/// How a 2-D instrument's rows are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Form {
    /// The four q rows of eq. 4.30, as the thesis writes them (its observability tables).
    Thesis,
    /// Decorrelated ([`Direction::Along`], [`Direction::Across`], [`Direction::Compat`]):
    /// the calibration's rows.
    Decorrelated,
    /// Decorrelated within each pose, the errors a setup's reset pose shares with its rows
    /// left in each row's [`Residual::reset_gain`] (covariance [`zero_covariance`]): for the
    /// planner, which adds a setup's poses one by one and marginalises the shared zero
    /// itself.
    PerPose,
}

/// [`residuals`] with the effects' corrections `corr` of every pose.
pub fn residuals_with(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
    corr: &Corrections,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PoseError> {
    residuals_in(
        campaign,
        p,
        model,
        step,
        p_cal,
        corr,
        noise,
        Form::Decorrelated,
    )
}

/// [`residuals_with`] in either [`Form`].
#[expect(
    clippy::too_many_arguments,
    reason = "the rows of one campaign: each argument is one independent input of the model"
)]
pub fn residuals_in(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
    corr: &Corrections,
    noise: &NoiseModel,
    form: Form,
) -> Result<Vec<Residual>, PoseError> {
    let eval = Evaluation {
        campaign,
        p,
        model,
        step,
        p_cal,
        corr,
        noise,
        form,
    };
    let pieces = Pieces::new(campaign, usize::MAX);
    let mut out = Vec::with_capacity(campaign.poses.len() * 4);
    for k in 0..pieces.len() {
        eval.piece_into(&pieces, k, &mut out)?;
    }
    Ok(out)
}

/// A campaign cut into pieces of at most `size` poses, in file order within each setup.
/// Consecutive setups share pieces (a piece's part of a setup reads that setup's reset
/// pose; a relative setup is never cut in two, its rows share its reset reading): the 1,043 self-calibration poses of 28 setups make 5 pieces, not 28, and a
/// campaign's 3,000 laser-tracker and grid-encoder setups of 10 poses 118, not 3,000 (a
/// piece's sums and its R factor cost the same for 10 poses as for 256; issue 30).
/// Drive-force setups keep pieces of their own: merged, the
/// sums of the online tracker's start calibration regroup, and that round-off alone moved
/// its six-minute drift test's share of checks below p = 0.01 from 0.033 to 0.074, past the
/// test's 0.05 (docs/calibration.md, "Since: pieces across setups"). Evaluated piece
/// by piece and concatenated, the rows are those of [`residuals_in`] in the same order; a
/// piece is the unit of parallel work of a large calibration, and fixed pieces make its
/// sums the same on any number of threads.
#[derive(Clone, Debug)]
pub struct Pieces {
    /// Per setup: its reset pose and its poses.
    setups: Vec<(Option<usize>, Vec<usize>)>,
    /// The pieces' parts, piece after piece: a setup and the range of that setup's poses.
    parts: Vec<(usize, std::ops::Range<usize>)>,
    /// Per piece: the range of its parts.
    spans: Vec<std::ops::Range<usize>>,
}

impl Pieces {
    pub fn new(campaign: &Campaign, size: usize) -> Pieces {
        let size = size.max(1);
        let setups: Vec<(Option<usize>, Vec<usize>)> = campaign
            .setups()
            .into_iter()
            .map(|s| (s.reset, s.poses))
            .collect();
        let mut cut = Cut {
            size,
            parts: Vec::new(),
            spans: Vec::new(),
            open: None,
        };
        for (k, (reset, poses)) in setups.iter().enumerate() {
            let shared = !poses
                .iter()
                .any(|&i| campaign.poses[i].instrument == Instrument::None);
            // a relative setup's rows share its reset reading: one piece holds them all
            let whole = reset.is_some_and(|r| campaign.poses[r].instrument.is_relative());
            cut.setup(k, poses.len(), shared, whole);
        }
        cut.close();
        Pieces {
            setups,
            parts: cut.parts,
            spans: cut.spans,
        }
    }

    pub fn len(&self) -> usize {
        self.spans.len()
    }

    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }
}

/// [`Pieces::new`]'s cutting, setup after setup.
struct Cut {
    size: usize,
    parts: Vec<(usize, std::ops::Range<usize>)>,
    spans: Vec<std::ops::Range<usize>>,
    /// The piece still open to the next setup: its first part and its poses so far.
    open: Option<(usize, usize)>,
}

impl Cut {
    /// Setup `k` of `n` poses; `shared`: a setup that may share a piece with its neighbours
    /// (every one but a drive-force one); `whole`: a setup never cut in two (a relative
    /// one: a piece holding it may exceed `size` by up to its length).
    fn setup(&mut self, k: usize, n: usize, shared: bool, whole: bool) {
        if !shared {
            self.close();
        }
        let mut a = 0usize;
        loop {
            let (first, held) = self.open.unwrap_or((self.parts.len(), 0));
            let b = if whole {
                n
            } else {
                n.min(a.saturating_add(self.size - held))
            };
            self.parts.push((k, a..b));
            self.open = Some((first, held + (b - a)));
            if held + (b - a) >= self.size || !shared {
                self.close();
            }
            if b == n {
                break;
            }
            a = b;
        }
    }

    /// Ends the open piece, if any.
    fn close(&mut self) {
        if let Some((first, _)) = self.open.take() {
            self.spans.push(first..self.parts.len());
        }
    }
}

/// One evaluation of a campaign's rows: at parameters `p` (virtual measurements made with
/// `p_cal`), with the effects' corrections `corr`, weighted by `noise`.
#[derive(Clone, Copy)]
pub struct Evaluation<'a> {
    pub campaign: &'a Campaign,
    pub p: &'a Params,
    pub model: Model,
    pub step: Step,
    pub p_cal: &'a Params,
    pub corr: &'a Corrections,
    pub noise: &'a NoiseModel,
    pub form: Form,
}

impl Evaluation<'_> {
    /// Appends the rows of piece `k` to `out`.
    pub fn piece_into(
        &self,
        pieces: &Pieces,
        k: usize,
        out: &mut Vec<Residual>,
    ) -> Result<(), PoseError> {
        let Some(parts) = pieces.spans.get(k) else {
            return Ok(());
        };
        let ctx = Ctx {
            p: self.p,
            p_cal: self.p_cal,
            model: self.model,
            corr: self.corr,
            noise: self.noise,
            decorrelated: self.form != Form::Thesis,
            shared: self.form == Form::Decorrelated,
            frames: geometry::frames(self.p),
        };
        // one buffer of the forward solves' sensitivities for the piece's poses
        let mut f = Forward::zeros();
        for (setup, range) in &pieces.parts[parts.clone()] {
            let (reset, poses) = &pieces.setups[*setup];
            self.part_into(&ctx, (*reset, poses), range.clone(), &mut f, out)?;
        }
        Ok(())
    }

    /// Appends the rows of the poses `range` of one setup (its reset pose and poses).
    fn part_into(
        &self,
        ctx: &Ctx,
        (reset, poses): (Option<usize>, &[usize]),
        range: std::ops::Range<usize>,
        f: &mut Forward,
        out: &mut Vec<Residual>,
    ) -> Result<(), PoseError> {
        let campaign = self.campaign;
        let reset = reset.map(|i| (i, &campaign.poses[i]));
        let mut at_reset = AtReset::default();
        // a reset pose that cannot be solved is blamed on its own line, not on the first
        // pose measured relative to it
        if let Some((ri, reset)) = reset.filter(|(_, r)| r.instrument.is_relative()) {
            let (p_r, q_r) = corrected(self.p, &reset.q, &self.corr.delta(ri));
            let nr = forward(&p_r, self.model, Subsystem::NR, &q_r)
                .map_err(|e| PoseError::at(campaign, reset, e))?;
            if self.step == Step::Direct {
                at_reset = AtReset::of(ctx, reset, (&p_r, &q_r), nr);
            }
        }
        let first = out.len();
        for &i in &poses[range.clone()] {
            let pose = &campaign.poses[i];
            if pose.reset && pose.instrument.is_relative() {
                continue;
            }
            let err = |error: ModelError| PoseError::at(campaign, pose, error);
            match self.step {
                Step::Direct => {
                    pose_rows(ctx, (i, pose), (reset, &at_reset), f, out).map_err(err)?;
                }
                Step::VirtualQ2 => {
                    virtual_q2_row(ctx, i, pose, self.p_cal, out).map_err(|e| err(e.into()))?;
                }
            }
        }
        // a relative setup is never split between pieces ([`Pieces::new`]): here are all
        // its rows
        if let Some((_, reset)) = reset.filter(|_| ctx.shared && self.step == Step::Direct) {
            let cov = zero_covariance(ctx.noise, (ctx.p_cal, ctx.model), reset)
                .map_err(|e| PoseError::at(campaign, reset, e))?;
            share_reset(&mut out[first..], &cov);
        }
        // the reset pose of a forward instrument still yields a virtual q2 measurement,
        // after the setup's last pose
        if self.step == Step::VirtualQ2 && range.end == poses.len() {
            if let Some((i, pose)) = reset {
                let err = |error| PoseError::at(campaign, pose, error);
                virtual_q2_row(ctx, i, pose, self.p_cal, out).map_err(err)?;
            }
        }
        Ok(())
    }
}

/// What every row of one evaluation shares.
struct Ctx<'a> {
    p: &'a Params,
    /// Parameters the rows' fixed combinations are built at (the calibration's start): a
    /// combination that moved with the parameters would make the Jacobian inexact.
    p_cal: &'a Params,
    model: Model,
    corr: &'a Corrections,
    noise: &'a NoiseModel,
    /// Whether a 2-D instrument's q rows are decorrelated (the calibration's form) or kept
    /// as the thesis writes them (its observability tables).
    decorrelated: bool,
    /// Whether a relative setup's rows are made independent of the zero they share
    /// ([`share_reset`]; not in [`Form::PerPose`]).
    shared: bool,
    /// The guides' frames of `p`, once per piece.
    frames: geometry::Frames,
}

/// What every pose of a relative setup reads of its reset pose, solved once for a piece's
/// part of the setup instead of once per pose (issue 30: a campaign of small setups paid
/// them per pose): the same solves of the same inputs, so the rows are the same to the
/// bit. A solve that failed here is left to the pose that reads it, which makes it again
/// and reports its error as before, on the pose's line.
#[derive(Default)]
struct AtReset {
    /// Through the redundant subsystem, at the reset's corrected inputs (2-D instruments).
    nr: Option<Forward>,
    /// Through each of [`FORWARD_SUBSYSTEMS`] (forward instruments).
    subs: [Option<Forward>; 2],
    /// The reset's TCP under `p_cal` without effects (the decorrelating gains).
    tcp_cal: Option<Vector2<f64>>,
}

impl AtReset {
    /// What the poses of `reset`'s setup read of it: `nr`, its solve through the redundant
    /// subsystem at its corrected inputs `p_r`, `q_r`, and the instrument's other solves.
    fn of(ctx: &Ctx, reset: &Pose, (p_r, q_r): (&Params, &[f64; 4]), nr: Forward) -> AtReset {
        use Instrument::{Dbb, Kgm, LiPsi, LiX, LiY, Lt};
        match reset.instrument {
            Lt | Kgm => AtReset {
                nr: Some(nr),
                tcp_cal: ctx
                    .decorrelated
                    .then(|| geometry::fgm(ctx.p_cal, ctx.model, reset.q[0], reset.q[3]).ok())
                    .flatten()
                    .map(|r| Vector2::new(r.x(), r.y())),
                ..AtReset::default()
            },
            Dbb | LiX | LiY | LiPsi => AtReset {
                subs: FORWARD_SUBSYSTEMS.map(|sub| forward(p_r, ctx.model, sub, q_r).ok()),
                ..AtReset::default()
            },
            _ => AtReset::default(),
        }
    }
}

fn pose_rows(
    ctx: &Ctx,
    (i, pose): (usize, &Pose),
    (reset, at): (Option<(usize, &Pose)>, &AtReset),
    f: &mut Forward,
    out: &mut Vec<Residual>,
) -> Result<(), ModelError> {
    use Instrument::{Dbb, Kgm, LiPsi, LiX, LiY, Lt, None, SelfCal};
    match (pose.instrument, reset) {
        (Lt, Some(reset)) => Ok(inverse_rows(
            ctx,
            XyInstrument::Lt,
            (i, pose),
            (reset, at),
            out,
        )?),
        (Kgm, Some(reset)) => Ok(inverse_rows(
            ctx,
            XyInstrument::Kgm,
            (i, pose),
            (reset, at),
            out,
        )?),
        (Dbb | LiX | LiY | LiPsi, Some(reset)) => Ok(forward_rows(ctx, i, pose, (reset, at), out)?),
        (SelfCal, _) => Ok(self_rows(ctx, (i, pose), f, out)?),
        (None, _) if pose.drives_loaded() => Ok(force_rows(ctx, i, pose, out)?),
        _ => Ok(()),
    }
}

/// Step of the central differences of the force rows' Jacobian: small against the
/// tolerances (0.1 mm, 1 mrad), large against the equilibrium's convergence (1e-9 of a
/// force of ~100 N), on a nearly linear map (forces are stiffness times incompatibility).
fn force_step(i: usize) -> f64 {
    if crate::params::unit(i) == crate::params::Unit::Rad {
        1e-6
    } else {
        1e-3
    }
}

/// The drive forces of the elasto-geometric model with all four drives position-controlled
/// at `q` (parameters `p`, stiffness `k`) and their derivatives by the 29 parameters: central
/// differences of the equilibrium, warm-started from its own (from `warm` where given: the
/// previous sample of a stream).
pub fn force_jacobian(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    warm: Option<&Equilibrium>,
) -> Result<(Equilibrium, [Row; 4]), ElasticError> {
    let eq: Equilibrium = match warm {
        Some(w) => fegm_from(p, k, q, ALL_ACTIVE, w)?,
        None => fegm(p, k, q, ALL_ACTIVE)?,
    };
    let mut dp = [Row::zeros(); 4];
    for j in 0..N_PARAMS {
        let h = force_step(j);
        let at = |sign: f64| -> Result<[f64; 4], ElasticError> {
            let mut pj = *p;
            pj[j] += sign * h;
            Ok(fegm_from(&pj, k, q, ALL_ACTIVE, &eq)?.drive_force)
        };
        let (plus, minus) = (at(1.0)?, at(-1.0)?);
        for a in 0..4 {
            dp[a][j] = (plus[a] - minus[a]) / (2.0 * h);
        }
    }
    Ok((eq, dp))
}

/// Drive-force rows (thesis 4.4, used as measurements): with all four drives
/// position-controlled at the recorded positions, the elasto-geometric model's drive forces
/// minus the recorded ones, f1..f4 (N), with the default stiffness times 1 + the effects'
/// stiffness change. Their derivatives by the 29 parameters (and, with effects, by the
/// carrier positions) by central differences of the equilibrium, warm-started from the
/// pose's own; by the stiffness change exactly f / (1 + dk): uniformly scaled springs deform
/// alike, only their forces scale. The effects' columns are the chain rule through these
/// ([`Delta::chain`]): a temperature that lengthens a rod enters the forces as it enters
/// the geometry.
///
/// In the calibration's form the rows carry the drives' position noise too (errors in
/// variables: [`noise::DriveNoise`]) and are decorrelated ([`decorrelate_forces`]); in the
/// thesis's form they are the four forces with the currents' noise alone (the observability
/// tables of the currents).
fn force_rows(
    ctx: &Ctx,
    i: usize,
    pose: &Pose,
    out: &mut Vec<Residual>,
) -> Result<(), ElasticError> {
    let d = ctx.corr.delta(i);
    let (p_i, q_i) = corrected(ctx.p, &pose.q, &d);
    let k = Stiffness::default().scaled(1.0 + d.dk);
    let (eq, dp) = force_jacobian(&p_i, &k, q_i, None)?;
    let mut sens = [InputSensitivity::default(); 4];
    for a in 0..4 {
        sens[a].dp = dp[a];
    }
    // the carrier positions matter only through an effect that moves them (a scale)
    if ctx.corr.n_params > 0 {
        let gains = force_position_gains(&p_i, &k, q_i, &eq)?;
        for (a, s) in sens.iter_mut().enumerate() {
            s.dq = std::array::from_fn(|b| gains[(a, b)]);
            s.dk = eq.drive_force[a] / (1.0 + d.dk);
        }
    }
    let parts = ctx.noise.force_parts();
    let mut rows: [Residual; 4] = std::array::from_fn(|a| Residual {
        pose: i,
        instrument: pose.instrument,
        direction: Direction::F(a),
        value: eq.drive_force[a] - pose.f[a],
        sigma: noise::sigma_of(&parts),
        parts,
        jacobian: sens[a].dp,
        d_pcal: None,
        d_theta: ctx.corr.theta_row(&[(i, sens[a])]),
        reset_gain: ResetGain::zeros(),
    });
    if ctx.decorrelated {
        // at the fixed p_cal: combinations that moved with the fit would make the
        // Jacobian inexact (as [`fixed_gains`] for a 2-D instrument)
        let k = Stiffness::default();
        let eq = fegm(ctx.p_cal, &k, pose.q, ALL_ACTIVE)?;
        let gains = force_position_gains(ctx.p_cal, &k, pose.q, &eq)?;
        decorrelate_forces(&mut rows, &ctx.noise.drives().modes(&gains));
    }
    out.extend(rows);
    Ok(())
}

/// The derivatives of the four drive forces by the four carrier positions (N/mm; row a:
/// force a, column b: carrier b) at `q` under `p` and `k`, all drives position-controlled:
/// central differences of the equilibrium, warm-started from `eq`, its own at `q`. What an
/// encoder's error does to the forces ([`noise::DriveNoise`]).
pub fn force_position_gains(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    eq: &Equilibrium,
) -> Result<Matrix4<f64>, ElasticError> {
    let mut gains = Matrix4::zeros();
    for b in 0..4 {
        let at = |sign: f64| -> Result<[f64; 4], ElasticError> {
            let mut qb = q;
            qb[b] += sign * 1e-3;
            Ok(fegm_from(p, k, qb, ALL_ACTIVE, eq)?.drive_force)
        };
        let (plus, minus) = (at(1.0)?, at(-1.0)?);
        for a in 0..4 {
            gains[(a, b)] = (plus[a] - minus[a]) / 2e-3;
        }
    }
    Ok(gains)
}

/// Replaces the four force rows of one pose by their combinations along `modes` (the
/// forces' noise diagonalised: [`noise::DriveNoise::modes`]), each with its own variance
/// parts: independent rows whatever the currents' and the encoders' levels, so that the
/// noise rounds estimate both.
fn decorrelate_forces(rows: &mut [Residual; 4], modes: &ForceModes) {
    let old = rows.clone();
    for (m, row) in rows.iter_mut().enumerate() {
        let w = modes.basis.column(m);
        combine_into(row, &old, |a| w[a], (Direction::FMode(m), modes.parts[m]));
    }
}

/// The drive-force rows of every pose of `campaign` with all four drives position-controlled,
/// whether or not forces were recorded (a pose without is read as zero force): the
/// observability of the currents on a planned design, where a machine consistent with `p`
/// has no preload to record.
pub fn force_residuals(
    campaign: &Campaign,
    p: &Params,
    corr: &Corrections,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PoseError> {
    let ctx = Ctx {
        p,
        p_cal: p,
        model: Model::M29,
        corr,
        noise,
        // the four forces as recorded, with the currents' noise alone
        decorrelated: false,
        shared: false,
        frames: geometry::frames(p),
    };
    let mut out = Vec::with_capacity(4 * campaign.poses.len());
    for (i, pose) in campaign.poses.iter().enumerate() {
        if pose.follower.iter().any(|f| *f) {
            continue;
        }
        force_rows(&ctx, i, pose, &mut out).map_err(|e| PoseError::at(campaign, pose, e))?;
    }
    Ok(out)
}

/// Inverse calibration rows (eq. 4.30) of a laser-tracker or grid-encoder pose.
fn inverse_rows(
    ctx: &Ctx,
    xy: XyInstrument,
    (i, pose): (usize, &Pose),
    ((ri, reset), at): ((usize, &Pose), &AtReset),
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    let (Some(mx), Some(my)) = (pose.x, pose.y) else {
        return Ok(());
    };
    let dpose = ctx.corr.delta(i);
    let own;
    let r = if let Some(r) = &at.nr {
        r
    } else {
        let (p_r, q_r) = corrected(ctx.p, &reset.q, &ctx.corr.delta(ri));
        own = forward(&p_r, ctx.model, Subsystem::NR, &q_r)?;
        &own
    };
    let (x, y) = (mx + dpose.dm.x + r.sol.c[X], my + dpose.dm.y + r.sol.c[Y]);
    let (p_i, q_i) = corrected(ctx.p, &pose.q, &dpose);
    let inv = geometry::solve(&p_i, ctx.model, Subsystem::Tcp, [x, y])?;
    let s = geometry::sensitivity(&p_i, ctx.model, Subsystem::Tcp, &inv)?;
    let first = out.len();
    for (a, &q_a) in q_i.iter().enumerate() {
        let v = q_var(a);
        let g = Vector2::new(s.dc_dk[(v, 0)], s.dc_dk[(v, 1)]);
        // dq/dp = ∂igm/∂p + ∂igm/∂X · d fgm(Q_reset)/dp
        let at_reset = input_sensitivity(r, Subsystem::NR, &[(X, g.x), (Y, g.y)]);
        let mut at_pose = InputSensitivity {
            dp: s.dc_dp.row(v).transpose(),
            dm: g,
            ..Default::default()
        };
        at_pose.dq[a] = -1.0;
        let parts = noise::add(
            ctx.noise.xy_parts(xy, Vector2::new(x, y), g),
            ctx.noise.encoder_parts(1.0),
        );
        out.push(Residual {
            pose: i,
            instrument: pose.instrument,
            direction: Direction::Q(a),
            value: inv.c[v] - q_a,
            sigma: noise::sigma_of(&parts),
            parts,
            jacobian: at_pose.dp + at_reset.dp,
            d_pcal: None,
            d_theta: ctx.corr.theta_row(&[(i, at_pose), (ri, at_reset)]),
            // the reset's reading error enters as the pose's own does, through X
            reset_gain: reset_gain(g, &at_reset.dq),
        });
    }
    if ctx.decorrelated {
        let (g_fixed, tcp) = fixed_gains(ctx, mx, my, (&reset.q, at.tcp_cal))?;
        let (ux, uy) = match xy {
            XyInstrument::Lt => ctx.noise.beam_frame(tcp),
            XyInstrument::Kgm => (Vector2::x(), Vector2::y()),
        };
        decorrelate(&mut out[first..], &g_fixed, ux, uy, ctx.noise, xy, tcp);
    }
    Ok(())
}

/// The gains dq/dX of the four drives at the recorded TCP, under the parameters `p_cal`
/// (fixed during a calibration) and without effects: the decorrelating combinations stay
/// the same while the parameters move, so the rows' Jacobian is exact.
fn fixed_gains(
    ctx: &Ctx,
    mx: f64,
    my: f64,
    (q_reset, reset_cal): (&[f64; 4], Option<Vector2<f64>>),
) -> Result<([Vector2<f64>; 4], Vector2<f64>), GeometryError> {
    let r = if let Some(r) = reset_cal {
        r
    } else {
        let r = geometry::fgm(ctx.p_cal, ctx.model, q_reset[0], q_reset[3])?;
        Vector2::new(r.x(), r.y())
    };
    let tcp = Vector2::new(mx + r.x, my + r.y);
    let inv = geometry::solve(ctx.p_cal, ctx.model, Subsystem::Tcp, [tcp.x, tcp.y])?;
    let s = geometry::sensitivity(ctx.p_cal, ctx.model, Subsystem::Tcp, &inv)?;
    let g = [0, 1, 2, 3].map(|a| {
        let v = q_var(a);
        Vector2::new(s.dc_dk[(v, 0)], s.dc_dk[(v, 1)])
    });
    Ok((g, tcp))
}

/// Replace the four q rows of one 2-D instrument pose (rows r = G e + n: G the 4 × 2
/// derivative of the drives by the TCP, e the instrument's error, n the encoders') by four
/// uncorrelated rows with a meaning: the TCP misfit −(GᵀG)⁻¹Gᵀ r along `u` and `v` (mm;
/// model minus measured), and the two combinations Uᵀ r orthogonal to G's columns, which the
/// instrument cannot reach (encoder noise only). Correlated rows counted as independent make
/// χ² and F-tests overconfident; these are independent up to the encoders' small share in
/// the misfit rows.
fn decorrelate(
    rows: &mut [Residual],
    g: &[Vector2<f64>; 4],
    u: Vector2<f64>,
    v: Vector2<f64>,
    noise: &NoiseModel,
    instrument: XyInstrument,
    tcp: Vector2<f64>,
) {
    if rows.len() != 4 {
        return;
    }
    let gm = nalgebra::Matrix4x2::from_rows(&[
        g[0].transpose(),
        g[1].transpose(),
        g[2].transpose(),
        g[3].transpose(),
    ]);
    let Some(gtg_inv) = (gm.transpose() * gm).try_inverse() else {
        return; // a singular pose: keep the q rows
    };
    let a = gtg_inv * gm.transpose(); // 2 × 4
                                      // orthonormal basis of the complement of G's columns
    let svd = gm.svd(true, false);
    let Some(uf) = svd.u else { return };
    let full = nalgebra::Matrix4::from_fn(|r, c| if c < 2 { uf[(r, c)] } else { 0.0 });
    let comp = complement(&full);
    let weights: [(Direction, nalgebra::RowVector4<f64>); 4] = [
        (Direction::Along, -(u.transpose() * a)),
        (Direction::Across, -(v.transpose() * a)),
        (Direction::Compat(0), comp[0]),
        (Direction::Compat(1), comp[1]),
    ];
    let old: Vec<Residual> = rows.to_vec();
    for (row, (direction, w)) in rows.iter_mut().zip(weights) {
        // wᵀ G is the row's gain on the instrument's (x, y) error; |w|² on the encoders'
        let gain = Vector2::new((w * gm.column(0))[0], (w * gm.column(1))[0]);
        let parts = noise::add(
            noise.xy_parts(instrument, tcp, gain),
            noise.encoder_parts(w.norm_squared()),
        );
        combine_into(row, &old, |k| w[k], (direction, parts));
    }
}

/// `row` made the combination Σ_k w(k) old_k of a pose's rows (value, parameters' and
/// effects' derivatives), with its own direction and variance parts: one decorrelated row.
fn combine_into(
    row: &mut Residual,
    old: &[Residual],
    w: impl Fn(usize) -> f64,
    (direction, parts): (Direction, Parts),
) {
    let mut value = 0.0;
    let mut jac = Row::zeros();
    let mut reset_gain = ResetGain::zeros();
    let mut d_theta = vec![0.0; old[0].d_theta.len()];
    for (k, o) in old.iter().enumerate() {
        value += w(k) * o.value;
        jac += o.jacobian * w(k);
        reset_gain += o.reset_gain * w(k);
        for (d, od) in d_theta.iter_mut().zip(&o.d_theta) {
            *d += w(k) * od;
        }
    }
    row.direction = direction;
    row.value = value;
    row.jacobian = jac;
    row.d_theta = d_theta;
    row.reset_gain = reset_gain;
    row.sigma = noise::sigma_of(&parts);
    row.parts = parts;
}

/// Covariance of the errors a setup's reset pose shares with all its rows, in the order of
/// [`ResetGain`]: the reading the instrument was zeroed on (at the reset pose; none for a
/// ball-bar, whose pivot is where the machine stood) and the reset pose's four encoders.
/// The reading's at the calibration's fixed `p_cal`, so that the rows' combinations stay put
/// while the parameters move.
pub fn zero_covariance(
    noise: &NoiseModel,
    (p_cal, model): (&Params, Model),
    reset: &Pose,
) -> Result<nalgebra::SMatrix<f64, 6, 6>, GeometryError> {
    let mut cov = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    for k in 2..6 {
        cov[(k, k)] = noise.encoder_mm.powi(2);
    }
    let reading = match (reset.instrument, XyInstrument::of(reset.instrument)) {
        (_, Some(xy)) => {
            let sol = geometry::fgm(p_cal, model, reset.q[0], reset.q[3])?;
            noise.xy_covariance(xy, Vector2::new(sol.x(), sol.y()))
        }
        (Instrument::LiX | Instrument::LiY | Instrument::LiPsi, None) => {
            let sigma = noise.scalar_sigma(reset.instrument).unwrap_or(0.0);
            nalgebra::Matrix2::new(sigma * sigma, 0.0, 0.0, 0.0)
        }
        _ => nalgebra::Matrix2::zeros(),
    };
    cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&reading);
    Ok(cov)
}

/// The rows of one relative setup made independent again. The setup was zeroed on a
/// reading as noisy as any other, so every row carries that reading's error e (covariance
/// `cov`) with its own gain g_i: with z = r/σ, cov(z) = I + H S Hᵀ (row i of H is g_iᵀ/σ_i,
/// S = `cov`), an offset per setup with a prior of one reading's noise, marginalised. Each
/// row becomes its row of cov(z)^(−1/2) z (value, parameters' and effects' derivatives
/// alike): with H S Hᵀ = Σ λ_k q_k q_kᵀ (rank six at most), z − Σ (1 − 1/√(1 + λ_k)) q_k
/// q_kᵀ z. Each row keeps its σ and its variance parts: the shared errors are the same
/// instruments' noise as the row's own (the reading's and the encoders'), so the noise
/// rounds estimate the level of one reading.
fn share_reset(rows: &mut [Residual], cov: &nalgebra::SMatrix<f64, 6, 6>) {
    if rows.iter().any(|r| !(r.sigma > 0.0)) {
        return;
    }
    let eig = cov.symmetric_eigen();
    let root = eig.eigenvectors
        * nalgebra::SMatrix::<f64, 6, 6>::from_diagonal(
            &eig.eigenvalues.map(|v| v.max(0.0).sqrt()),
        )
        * eig.eigenvectors.transpose();
    let k: Vec<nalgebra::SMatrix<f64, 1, 6>> = rows
        .iter()
        .map(|r| r.reset_gain.transpose() / r.sigma * root)
        .collect();
    let m = k
        .iter()
        .fold(nalgebra::SMatrix::<f64, 6, 6>::zeros(), |m, ki| {
            m + ki.transpose() * ki
        });
    let modes = m.symmetric_eigen();
    for c in 0..6 {
        let lambda = modes.eigenvalues[c];
        if !(lambda > 1e-12) {
            continue;
        }
        let v = modes.eigenvectors.column(c);
        let q: Vec<f64> = k.iter().map(|ki| (ki * v)[0] / lambda.sqrt()).collect();
        let beta = 1.0 - 1.0 / (1.0 + lambda).sqrt();
        shrink_along(rows, &q, beta);
    }
}

/// z ← z − β q (qᵀ z) for every column of the rows (z = r/σ): value, parameters' and
/// effects' derivatives.
fn shrink_along(rows: &mut [Residual], q: &[f64], beta: f64) {
    let n_theta = rows.first().map_or(0, |r| r.d_theta.len());
    let (mut value, mut jac, mut theta) = (0.0, Row::zeros(), vec![0.0; n_theta]);
    for (r, qi) in rows.iter().zip(q) {
        let w = qi / r.sigma;
        value += w * r.value;
        jac += r.jacobian * w;
        for (t, d) in theta.iter_mut().zip(&r.d_theta) {
            *t += w * d;
        }
    }
    for (r, qi) in rows.iter_mut().zip(q) {
        let a = beta * qi * r.sigma;
        r.value -= a * value;
        r.jacobian -= jac * a;
        for (d, t) in r.d_theta.iter_mut().zip(&theta) {
            *d -= a * t;
        }
    }
}

/// Two orthonormal rows spanning the complement of the first two columns of `basis`
/// (orthonormal): Gram-Schmidt of the unit vector that keeps the most of itself, twice (of
/// the four, the best keeps at least 1/√2, then 1/2, so none is ever near zero).
fn complement(basis: &nalgebra::Matrix4<f64>) -> [nalgebra::RowVector4<f64>; 2] {
    let mut found = [
        basis.column(0).into_owned(),
        basis.column(1).into_owned(),
        nalgebra::Vector4::zeros(),
        nalgebra::Vector4::zeros(),
    ];
    for slot in 2..4 {
        let rest = |e: usize| {
            let mut w = nalgebra::Vector4::zeros();
            w[e] = 1.0;
            for b in &found[..slot] {
                w -= b * b.dot(&w);
            }
            w
        };
        let best = (0..4)
            .map(rest)
            .max_by(|a, b| a.norm().total_cmp(&b.norm()))
            .unwrap_or_default();
        found[slot] = best.normalize();
    }
    [found[2].transpose(), found[3].transpose()]
}

/// Forward calibration rows (eq. 4.31): relative distance, coordinate or angle through each
/// forward subsystem.
fn forward_rows(
    ctx: &Ctx,
    i: usize,
    pose: &Pose,
    ((ri, reset), at): ((usize, &Pose), &AtReset),
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    let (dpose, dreset) = (ctx.corr.delta(i), ctx.corr.delta(ri));
    let (p_i, q_i) = corrected(ctx.p, &pose.q, &dpose);
    let (p_r, q_r) = corrected(ctx.p, &reset.q, &dreset);
    for (sub, solved) in FORWARD_SUBSYSTEMS.into_iter().zip(&at.subs) {
        let now = forward(&p_i, ctx.model, sub, &q_i)?;
        let own;
        let zero = if let Some(zero) = solved {
            zero
        } else {
            own = forward(&p_r, ctx.model, sub, &q_r)?;
            &own
        };
        let d = |v: usize| now.sol.c[v] - zero.sol.c[v];
        // the reset pose's encoders are the whole setup's: in its shared part
        let var = |v: usize| encoder_gain2(&now, v);
        let inst = pose.instrument;
        // the value as Σ g_v · Δc_v − (measured + dm_w): g has two terms (x, y of the
        // ball-bar's direction); a single coordinate pads it with a zero-weight term
        let (direction, value, g, w, var_enc) = match inst {
            Instrument::Dbb => {
                let Some(r) = pose.r else { return Ok(()) };
                let (dx, dy) = (d(X), d(Y));
                let dist = dx.hypot(dy);
                if dist < 1e-9 {
                    continue;
                }
                let (ux, uy) = (dx / dist, dy / dist);
                let var_enc = ux * ux * var(X) + uy * uy * var(Y);
                let g = [(X, ux), (Y, uy)];
                (
                    Direction::R(a_of(sub), b_of(sub)),
                    dist - r,
                    g,
                    None,
                    var_enc,
                )
            }
            // one coordinate relative to the reset pose: x, y or ψ
            Instrument::LiX | Instrument::LiY | Instrument::LiPsi => {
                let (v, measured, direction, w) = match inst {
                    Instrument::LiX => (X, pose.x, Direction::X(a_of(sub), b_of(sub)), Some(0)),
                    Instrument::LiY => (Y, pose.y, Direction::Y(a_of(sub), b_of(sub)), Some(1)),
                    _ => (PSI, pose.psi, Direction::Psi(a_of(sub), b_of(sub)), None),
                };
                let Some(m) = measured else { return Ok(()) };
                // the reading's correction: x or y of dm, or dpsi for the angle
                let dm = w.map_or(dpose.dpsi, |k| dpose.dm[k]);
                (direction, d(v) - m - dm, [(v, 1.0), (v, 0.0)], w, var(v))
            }
            _ => return Ok(()),
        };
        let mut at_pose = input_sensitivity(&now, sub, &g);
        match (w, direction) {
            (Some(k), _) => at_pose.dm[k] = -1.0,
            (None, Direction::Psi(..)) => at_pose.dpsi = -1.0,
            (None, _) => {}
        }
        let at_reset = negated(input_sensitivity(zero, sub, &g));
        let parts = noise::add(
            ctx.noise.scalar_parts(inst, 1.0),
            ctx.noise.encoder_parts(var_enc),
        );
        out.push(Residual {
            pose: i,
            instrument: inst,
            direction,
            value,
            sigma: noise::sigma_of(&parts),
            parts,
            jacobian: at_pose.dp + at_reset.dp,
            d_pcal: None,
            d_theta: ctx.corr.theta_row(&[(i, at_pose), (ri, at_reset)]),
            // an interferometer is zeroed on a reading; a ball-bar's pivot is where the
            // machine stood, read by no instrument
            reset_gain: reset_gain(
                if inst == Instrument::Dbb {
                    Vector2::zeros()
                } else {
                    Vector2::x()
                },
                &at_reset.dq,
            ),
        });
    }
    Ok(())
}

fn a_of(sub: Subsystem) -> usize {
    match sub {
        Subsystem::Actuators(a, _) => a,
        Subsystem::Tcp => 0,
    }
}

fn b_of(sub: Subsystem) -> usize {
    match sub {
        Subsystem::Actuators(_, b) => b,
        Subsystem::Tcp => 0,
    }
}

/// Self-calibration rows (eq. 4.37): followers q2, q3 against rgm(q1, q4).
fn self_rows(
    ctx: &Ctx,
    (i, pose): (usize, &Pose),
    f: &mut Forward,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    // without effects the pose's inputs are the machine's and the recorded positions
    // themselves: no correction (0.5 kB) built, added and copied per pose
    let own;
    let (p_i, q_i) = if ctx.corr.is_empty() {
        (ctx.p, pose.q)
    } else {
        own = corrected(ctx.p, &pose.q, &ctx.corr.delta(i));
        (&own.0, own.1)
    };
    // the guides' frames of the piece's machine where the correction leaves its guides as
    // they are (every pose without effects): two sin_cos less per pose
    let same_guides = [D1, GAMMA1, D2, GAMMA2]
        .iter()
        .all(|&k| p_i[k].to_bits() == ctx.p[k].to_bits());
    let mine;
    let frames = if same_guides {
        &ctx.frames
    } else {
        mine = geometry::frames(p_i);
        &mine
    };
    let sub = Subsystem::NR;
    f.sol = geometry::fgm_with_frames(p_i, frames, ctx.model, sub, [q_i[0], q_i[3]])?;
    // only the followers' rows of the sensitivities: what these rows read
    let vars = [q_var(1), q_var(2)];
    geometry::sensitivity_rows_into(p_i, ctx.model, (sub, &f.sol), frames, &vars, &mut f.sens)?;
    for a in [1, 2] {
        let v = q_var(a);
        // the follower's own encoder and those of q1, q4 through rgm
        let parts = ctx.noise.encoder_parts(1.0 + encoder_gain2(f, v));
        // the sensitivity to the pose's inputs only where effects read it: without, the
        // row's derivatives are the solve's own (1.2 kB less copied per row)
        let d_theta = if ctx.corr.n_params == 0 {
            Vec::new()
        } else {
            let mut at_pose = input_sensitivity(f, Subsystem::NR, &[(v, 1.0)]);
            at_pose.dq[a] -= 1.0;
            ctx.corr.theta_row(&[(i, at_pose)])
        };
        out.push(Residual {
            pose: i,
            instrument: pose.instrument,
            direction: Direction::Q(a),
            value: f.sol.c[v] - q_i[a],
            sigma: noise::sigma_of(&parts),
            parts,
            jacobian: f.sens.dc_dp.row(v).transpose(),
            d_pcal: None,
            d_theta,
            reset_gain: ResetGain::zeros(),
        });
    }
    Ok(())
}

/// Second step of the forward instruments (eq. 4.32): X_e = fgm(Q_nr, P_cal), q2 = igm(X_e, P).
/// The effects' corrections apply to both models, with their parameters held fixed.
fn virtual_q2_row(
    ctx: &Ctx,
    i: usize,
    pose: &Pose,
    p_cal: &Params,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    use Instrument::{Dbb, LiPsi, LiX, LiY};
    if !matches!(pose.instrument, Dbb | LiX | LiY | LiPsi) {
        return Ok(());
    }
    let d = ctx.corr.delta(i);
    let (p_i, q_i) = corrected(ctx.p, &pose.q, &d);
    let (p_cal_i, _) = corrected(p_cal, &pose.q, &d);
    let model = ctx.model;
    let xe = geometry::fgm(&p_cal_i, model, q_i[0], q_i[3])?;
    let xe_sens = geometry::sensitivity(&p_cal_i, model, Subsystem::NR, &xe)?;
    let inv = geometry::igm(&p_i, model, xe.x(), xe.y())?;
    let s = geometry::sensitivity(&p_i, model, Subsystem::Tcp, &inv)?;
    let v = q_var(1);
    let d_pcal: Row = (xe_sens.dc_dp.row(X) * s.dc_dk[(v, 0)]
        + xe_sens.dc_dp.row(Y) * s.dc_dk[(v, 1)])
        .transpose();
    out.push(Residual {
        pose: i,
        instrument: pose.instrument,
        direction: Direction::VirtualQ2,
        value: inv.c[v] - q_i[1],
        sigma: ctx.noise.encoder_mm * 2f64.sqrt(),
        parts: ctx.noise.encoder_parts(2.0),
        jacobian: s.dc_dp.row(v).transpose(),
        d_pcal: Some(Box::new(d_pcal)),
        d_theta: vec![0.0; ctx.corr.n_params],
        reset_gain: ResetGain::zeros(),
    });
    Ok(())
}

/// Whether a campaign has rows of the given kind.
pub fn has_forward_instruments(campaign: &Campaign) -> bool {
    campaign.poses.iter().any(|p| {
        matches!(
            p.instrument,
            Instrument::Dbb | Instrument::LiX | Instrument::LiY | Instrument::LiPsi
        )
    })
}

/// One held-out TCP error: the model's relative TCP from the recorded actuators minus the
/// instrument's reading, in one coordinate.
#[derive(Clone, Debug, PartialEq)]
pub struct TcpError {
    /// Index of the pose in the campaign.
    pub pose: usize,
    /// `x`, `y` or `r` (ball-bar distance).
    pub coordinate: &'static str,
    /// Error, mm.
    pub value: f64,
    /// d value / d θ over the effects' parameters (empty without effects).
    pub d_theta: Vec<f64>,
}

/// TCP position error of held-out poses (µm-ready, mm here): for every non-reset pose of a
/// relative TCP instrument, the model's TCP from the recorded actuators (fgm of (q1, q4),
/// relative to the setup's reset pose) minus the instrument's reading, per measured coordinate
/// (x, y, or the ball-bar distance). Returns (pose index, coordinate name, error mm).
pub fn tcp_errors(
    campaign: &Campaign,
    p: &Params,
    model: Model,
) -> Result<Vec<(usize, &'static str, f64)>, PoseError> {
    Ok(
        tcp_errors_with(campaign, p, model, &Corrections::default())?
            .into_iter()
            .map(|e| (e.pose, e.coordinate, e.value))
            .collect(),
    )
}

/// [`tcp_errors`] under the effects' corrections, with the errors' sensitivities to the
/// effects' parameters (to re-fit setup-local ones on held-out setups).
pub fn tcp_errors_with(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    corr: &Corrections,
) -> Result<Vec<TcpError>, PoseError> {
    let mut out = Vec::new();
    for setup in campaign.setups() {
        let Some(ri) = setup.reset else { continue };
        let reset = &campaign.poses[ri];
        for &i in &setup.poses {
            let pose = &campaign.poses[i];
            if pose.reset || !pose.instrument.is_relative() {
                continue;
            }
            let (dpose, dreset) = (corr.delta(i), corr.delta(ri));
            let (p_i, q_i) = corrected(p, &pose.q, &dpose);
            let (p_r, q_r) = corrected(p, &reset.q, &dreset);
            let now = forward(&p_i, model, Subsystem::NR, &q_i)
                .map_err(|e| PoseError::at(campaign, pose, e))?;
            // a reset pose that cannot be solved is blamed on its own line
            let zero = forward(&p_r, model, Subsystem::NR, &q_r)
                .map_err(|e| PoseError::at(campaign, reset, e))?;
            let (dx, dy) = (now.sol.c[X] - zero.sol.c[X], now.sol.c[Y] - zero.sol.c[Y]);
            let mut push = |coordinate, value, g: &[(usize, f64)], dm: Vector2<f64>| {
                let mut at_pose = input_sensitivity(&now, Subsystem::NR, g);
                at_pose.dm = dm;
                let at_reset = negated(input_sensitivity(&zero, Subsystem::NR, g));
                out.push(TcpError {
                    pose: i,
                    coordinate,
                    value,
                    d_theta: corr.theta_row(&[(i, at_pose), (ri, at_reset)]),
                });
            };
            if let Some(m) = pose.x {
                push(
                    "x",
                    dx - m - dpose.dm.x,
                    &[(X, 1.0)],
                    Vector2::new(-1.0, 0.0),
                );
            }
            if let Some(m) = pose.y {
                push(
                    "y",
                    dy - m - dpose.dm.y,
                    &[(Y, 1.0)],
                    Vector2::new(0.0, -1.0),
                );
            }
            if let Some(m) = pose.r {
                let dist = dx.hypot(dy).max(1e-12);
                let g = [(X, dx / dist), (Y, dy / dist)];
                push("r", dx.hypot(dy) - m, &g, Vector2::zeros());
            }
        }
    }
    Ok(out)
}
