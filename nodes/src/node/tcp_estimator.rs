//! `tcp_estimator`: for every ActuatorState, the elasto-geometric TCP estimate
//! (`rpkm_core::elastic::fegm_checked_after`, warm-started from the previous equilibrium, its
//! rigid reference from the previous rigid ψ) with the current parameters, published as
//! TcpEstimate with the state's stamp and seq.
//!
//! Every elastic equilibrium passes the core's plausibility checks before it is published
//! (loop closure, platform balance, forces within 10× the drives, ψ near γ2, TCP within 2 mm
//! of the rigid model: `rpkm_core::elastic::plausibility`): a warm-started solve can land on a
//! non-physical branch after a large jump and still converge. A warm result that fails is
//! solved again cold; when that fails too, the pose comes from the rigid forward model of
//! (q1, q4) and the message says so: `converged = false`, `iterations = 0`, rod and drive
//! forces 0, loop residuals those of the rigid pose (they show the incompatibility). Every
//! estimate says how it was obtained (`outcome`: OK, WARM_REJECTED_COLD_OK, RIGID_FALLBACK)
//! and which check rejected the elastic solve (`reason`, the core's [`Reason`] code); the
//! reasons are also counted on /diagnostics (WARN; ERROR while it persists). A state no model can
//! solve gets no estimate. ψ is published wrapped to (−π, π].
//! The estimate needs the positions alone: drive forces not measured (NaN, a cell without
//! force sensing) change nothing, unless a calibrated effect reads them: then the state gets
//! no estimate, counted (`forces_not_measured`) and named on /diagnostics (WARN).
//! With `views` on (default with DDS output) every `view_every`-th estimate is also published
//! as `geometry_msgs/PoseStamped` on `/rpkm/tcp_pose` and `tf2_msgs/TFMessage` on `/tf`
//! ([`super::views`]).
//! Per sample nothing is allocated: static nalgebra types, a `Copy` message, zero-copy
//! publishing on iceoryx2.

use std::time::Duration;

use rpkm_core::elastic::{fegm_checked_after, wrap_angle, Checked, ElasticError, Limits, Reason};
use rpkm_core::geometry::{self, carrier_joint, platform_joint};
use rpkm_core::params::{Model, Params, RODS};
use rpkm_msgs::{ActuatorState, DiagnosticStatus, TcpEstimate};
use rpkm_transport::topic;

use super::context::{status, CommonArgs, Every, Idle, NodeContext};
use super::declare::{keys, served, ParamDefault, ParamSpec};
use super::geometry::Geometry;
use super::geometry::GEOMETRY;
use super::inputs::{self, DriveInput, ParameterFollower, SeqGaps, StreamMotion, UnmeasuredForce};
use super::lifecycle::Lifecycle;
use super::params::NodeParams;
use super::realtime::{BUSY_POLL, PRIORITY};
use super::views::{self, TcpViews};
use crate::units::{seconds_from_ms, set_tcp_position_mm};
use rpkm_transport::Backend;

/// Parameter `views` of the node.
const VIEWS: ParamSpec = ParamSpec {
    description: "publish /rpkm/tcp_pose (PoseStamped) and /tf (machine -> platform) on DDS",
    ..views::VIEWS
};
/// Parameter `view_every` of the node.
const VIEW_EVERY: ParamSpec = ParamSpec {
    description: "publish the views of every N-th estimate",
    ..views::VIEW_EVERY_PARAM
};
/// The node's own parameters: `view_every` live, the rest need a restart.
pub const PARAMS: [ParamSpec; 4] = [BUSY_POLL, PRIORITY, VIEWS, VIEW_EVERY];

/// Consecutive estimates without a plausible elastic equilibrium from which /diagnostics
/// says ERROR instead of WARN: one odd sample is a warning, a stream of them means the
/// parameters or the input no longer describe the machine.
pub const ERROR_AFTER_CONSECUTIVE: u64 = 50;

/// Counters of an [`Estimator`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EstimatorCounts {
    /// Estimates published.
    pub estimates: u64,
    /// Elastic solves that needed a cold start (the warm start failed or there was none).
    pub cold_starts: u64,
    /// Warm-started solves rejected (solver failure or a failed plausibility check) and
    /// solved again cold.
    pub warm_rejected: u64,
    /// Estimates from the rigid fallback (published with `converged = false`).
    pub rigid_fallbacks: u64,
    /// Of these, those whose elastic solve converged but failed the checks even cold.
    pub implausible: u64,
    /// States no model could solve (no estimate).
    pub unsolved: u64,
    /// Rigid fallbacks and unsolved states in a row, up to now (0 after a plausible one).
    pub consecutive_failures: u64,
    /// Rejections (warm and cold) by [`Reason`], indexed by `code − 1`.
    pub by_reason: [u64; 6],
    /// States not estimated: a calibrated effect reads a drive force they do not measure.
    pub forces_not_measured: u64,
}

impl EstimatorCounts {
    fn reject(&mut self, r: Reason) {
        self.by_reason[usize::from(r.code() - 1)] += 1;
    }
}

/// The estimator's state: the geometry and the previous checked solve (warm start of the
/// equilibrium and of the rigid reference).
#[derive(Debug, Clone)]
pub struct Estimator {
    geometry: Geometry,
    limits: Limits,
    previous: Option<Checked>,
    /// Counters.
    pub counts: EstimatorCounts,
    /// The last elastic failure (kept typed: formatted only for /diagnostics).
    pub last_error: Option<ElasticError>,
    /// Why the last rejected warm start was rejected.
    pub last_warm_rejection: Option<Reason>,
    /// Gaps in the input's seq (states lost before they reached the estimator).
    pub input: SeqGaps,
    /// How the stream's carriers moved (what a calibrated effect may read).
    motion: StreamMotion,
    /// Why the last state not estimated for a force it does not measure was not.
    pub last_unmeasured: Option<UnmeasuredForce>,
}

/// The reason an elastic failure counts under.
fn reason_of(e: &ElasticError) -> Reason {
    match e {
        ElasticError::Implausible(v) => v.reason,
        _ => Reason::NotConverged,
    }
}

impl Estimator {
    /// An estimator with `geometry` and the core's default plausibility limits.
    pub fn new(geometry: Geometry) -> Self {
        Self {
            geometry,
            limits: Limits::default(),
            previous: None,
            counts: EstimatorCounts::default(),
            last_error: None,
            last_warm_rejection: None,
            input: SeqGaps::default(),
            motion: StreamMotion::default(),
            last_unmeasured: None,
        }
    }

    /// The current geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// Replaces the geometry (a new Parameters message); the next solve starts cold.
    pub fn set_geometry(&mut self, geometry: Geometry) {
        self.geometry = geometry;
        self.previous = None;
    }

    /// The estimate answering `state`, or `None` when neither the elastic nor the rigid model
    /// solves it.
    pub fn estimate(&mut self, state: &ActuatorState) -> Option<TcpEstimate> {
        self.input.next(state.seq);
        // the carriers and parameters under the calibrated effects
        let (params, q) = match self.motion.model_inputs(&mut self.geometry, state) {
            Ok(inputs) => inputs,
            Err(e) => {
                self.counts.forces_not_measured += 1;
                self.last_unmeasured = Some(e);
                return None;
            }
        };
        let g = &self.geometry;
        let prev = self.previous.as_ref();
        let solved =
            fegm_checked_after(&params, &g.stiffness, q, state.follower, prev, &self.limits);
        let model = match g.model {
            Model::M24 => TcpEstimate::MODEL_24,
            Model::M29 => TcpEstimate::MODEL_29,
        };
        let mut est = TcpEstimate {
            stamp: state.stamp,
            seq: state.seq,
            model,
            outcome: TcpEstimate::OUTCOME_OK,
            reason: TcpEstimate::REASON_NONE,
            ..Default::default()
        };
        match solved {
            Ok(s) => {
                let c = &mut self.counts;
                c.cold_starts += u64::from(s.cold);
                if let Some(v) = s.warm_rejected {
                    c.warm_rejected += 1;
                    c.reject(v.reason);
                    self.last_warm_rejection = Some(v.reason);
                    est.outcome = TcpEstimate::OUTCOME_WARM_REJECTED_COLD_OK;
                    est.reason = v.reason.code();
                }
                c.consecutive_failures = 0;
                let eq = s.eq;
                self.previous = Some(s);
                est.psi = wrap_angle(eq.psi);
                est.rod_forces = eq.rod_force;
                est.drive_forces = eq.drive_force;
                est.iterations = u32::try_from(eq.iterations).unwrap_or(u32::MAX);
                est.converged = true;
                let loops = loop_residuals((&params, g.model), &q, eq.x, eq.y, eq.psi);
                set_tcp_position_mm(&mut est, (eq.x, eq.y), loops);
            }
            Err(e) => return self.rigid_fallback(e, (&params, &q), est),
        }
        self.counts.estimates += 1;
        Some(est)
    }

    /// No plausible elastic equilibrium: the rigid model of (q1, q4) at `params` (under the
    /// effects), flagged `converged = false`, or no estimate when that fails too.
    fn rigid_fallback(
        &mut self,
        e: ElasticError,
        (params, q): (&Params, &[f64; 4]),
        mut est: TcpEstimate,
    ) -> Option<TcpEstimate> {
        let c = &mut self.counts;
        c.cold_starts += 1;
        c.consecutive_failures = c.consecutive_failures.saturating_add(1);
        if let ElasticError::Implausible(v) = &e {
            c.reject(v.reason);
        }
        self.previous = None;
        let model = self.geometry.model;
        let rigid = geometry::fgm(params, model, q[0], q[3]);
        self.last_error = Some(e);
        let Ok(rigid) = rigid else {
            self.counts.unsolved += 1;
            return None;
        };
        if matches!(self.last_error, Some(ElasticError::Implausible(_))) {
            self.counts.implausible += 1;
        }
        self.counts.rigid_fallbacks += 1;
        est.psi = wrap_angle(rigid.psi());
        est.converged = false;
        est.outcome = TcpEstimate::OUTCOME_RIGID_FALLBACK;
        est.reason = self.last_error.as_ref().map_or(0, |e| reason_of(e).code());
        est.iterations = 0;
        let loops = loop_residuals((params, model), q, rigid.x(), rigid.y(), rigid.psi());
        set_tcp_position_mm(&mut est, (rigid.x(), rigid.y()), loops);
        self.counts.estimates += 1;
        Some(est)
    }

    /// The /diagnostics status of the estimator: OK while every estimate is a plausible
    /// elastic equilibrium, WARN once one was not (rigid fallback or unsolved) or once input
    /// states were lost (a gap in their seq), ERROR while [`ERROR_AFTER_CONSECUTIVE`] or more
    /// in a row had no plausible equilibrium.
    pub fn status(&self, node: &str) -> DiagnosticStatus {
        let c = self.counts;
        let last = self.last_error.as_ref();
        let last_text = last.map_or_else(|| "none".to_owned(), ToString::to_string);
        let (mut level, mut message) = if c.consecutive_failures >= ERROR_AFTER_CONSECUTIVE {
            (
                DiagnosticStatus::ERROR,
                format!(
                    "{} estimates in a row without a plausible elastic equilibrium (rigid \
                     model published, converged false); last: {last_text}",
                    c.consecutive_failures
                ),
            )
        } else if c.unsolved > 0 || c.rigid_fallbacks > 0 {
            (
                DiagnosticStatus::WARN,
                format!(
                    "{} rigid fallbacks ({} implausible), {} unsolved states; last elastic \
                     error: {last_text}",
                    c.rigid_fallbacks, c.implausible, c.unsolved
                ),
            )
        } else {
            (
                DiagnosticStatus::OK,
                format!(
                    "{} estimates, all plausible elastic equilibria ({} warm starts rejected \
                     and solved cold)",
                    c.estimates, c.warm_rejected
                ),
            )
        };
        if let Some(lost) = self.input.summary() {
            level = level.max(DiagnosticStatus::WARN);
            message = format!("{message}; input: {lost}");
        }
        if let Some(e) = &self.last_unmeasured {
            level = level.max(DiagnosticStatus::WARN);
            message = format!(
                "{message}; {} states not estimated: {e}",
                c.forces_not_measured
            );
        }
        let mut values = vec![
            ("estimates", c.estimates.to_string()),
            ("cold_starts", c.cold_starts.to_string()),
            ("warm_rejected", c.warm_rejected.to_string()),
            (
                "last_warm_rejection",
                self.last_warm_rejection
                    .map_or("none", Reason::as_str)
                    .into(),
            ),
            ("rigid_fallbacks", c.rigid_fallbacks.to_string()),
            ("implausible", c.implausible.to_string()),
            ("unsolved", c.unsolved.to_string()),
            ("consecutive_failures", c.consecutive_failures.to_string()),
            ("forces_not_measured", c.forces_not_measured.to_string()),
            (
                "last_reason",
                last.map_or("none", |e| reason_of(e).as_str()).into(),
            ),
            (
                "last_reason_code",
                last.map_or(0, |e| reason_of(e).code()).to_string(),
            ),
        ];
        for r in Reason::ALL {
            let key = REJECTION_KEYS[usize::from(r.code() - 1)];
            values.push((key, c.by_reason[usize::from(r.code() - 1)].to_string()));
        }
        values.extend(self.input.values());
        values.push(("parameters", self.geometry.source.clone()));
        status(level, node, message, values)
    }
}

/// /diagnostics keys of the rejection counts, in [`Reason`] code order.
const REJECTION_KEYS: [&str; 6] = [
    "rejected_not_converged",
    "rejected_loop_closure",
    "rejected_force_balance",
    "rejected_force_limit",
    "rejected_platform_angle",
    "rejected_far_from_rigid",
];

/// |A_i − B_i| − l_i of rods 1..5 of parameters `p` at pose (x, y, ψ) (mm) and carrier
/// positions `q` (mm), in mm; rod 5 is 0 for model 24.
fn loop_residuals(
    (p, model): (&Params, Model),
    q: &[f64; 4],
    x: f64,
    y: f64,
    psi: f64,
) -> [f64; 5] {
    let mut out = [0.0; 5];
    let rods = match model {
        Model::M24 => 4,
        Model::M29 => 5,
    };
    for (slot, rod) in out.iter_mut().zip(&RODS[..rods]) {
        let a = platform_joint(p, rod, x, y, psi);
        let b = carrier_joint(p, rod, q[rod.actuator]);
        *slot = (a - b).norm() - p[rod.l];
    }
    out
}

/// The node's parameters on its ROS 2 parameter services: model, stiffness and `view_every`
/// live (taken between samples; a new geometry is solved cold), the rest need a restart.
/// `views_default`: whether the views are on unless a file says otherwise (DDS output).
fn specs(views_default: bool) -> Vec<ParamSpec> {
    let mut specs = served(&[&PARAMS, &GEOMETRY]);
    for s in &mut specs {
        if s.key == VIEWS.key {
            s.default = ParamDefault::Bool(views_default);
        }
    }
    specs
}

/// What a parameter set changes while the node runs: the geometry and `view_every`.
fn configure(p: &NodeParams) -> anyhow::Result<(Geometry, u64)> {
    let every = VIEW_EVERY.u64(p).map_err(super::context::bad_param)?;
    Ok((Geometry::from_params(p)?, every))
}

/// A lifecycle configure: the parameters read again from the node's files, its geometry and
/// views set from them; `Err` names what is wrong (the node stays as it was).
fn reconfigure(
    args: &CommonArgs,
    ctx: &NodeContext,
    declared: &[&str],
    est: &mut Estimator,
    views: Option<&mut TcpViews>,
) -> Result<(), String> {
    let p = ctx
        .reread_params(args, "tcp_estimator", declared)
        .map_err(|e| crate::error::error_chain(&e))?;
    let (g, every) = configure(&p).map_err(|e| crate::error::error_chain(&e))?;
    est.set_geometry(g);
    if let Some(v) = views {
        v.set_every(every);
    }
    Ok(())
}

/// Every parameter the node declares besides the common ones.
pub fn declarations() -> Vec<ParamSpec> {
    inputs::with_drive_input([PARAMS.as_slice(), &GEOMETRY].concat())
}

/// Every parameter key the node declares besides the common ones.
pub fn declared() -> Vec<&'static str> {
    keys(&[&declarations()])
}

/// Applies a parameter set the services accepted: the geometry (solved cold from the next
/// state), `view_every`, the drive input's followers.
fn apply_set(
    ctx: &NodeContext,
    (p, names): (NodeParams, Vec<String>),
    (est, views, input): (&mut Estimator, Option<&mut TcpViews>, &mut DriveInput),
) -> anyhow::Result<()> {
    let (g, every) = configure(&p)?;
    if names.iter().any(|k| super::geometry::is_geometry_key(k)) {
        est.set_geometry(g);
    }
    if let Some(v) = views {
        v.set_every(every);
    }
    input.configure(ctx, &p)?;
    ctx.log(format!("parameters set: {}", names.join(", ")));
    Ok(())
}

/// Runs the node until SIGINT/SIGTERM.
pub fn run(args: &CommonArgs) -> anyhow::Result<()> {
    let declared = declared();
    let extra = inputs::extra_backend(args, "tcp_estimator")?;
    let ctx = NodeContext::open("tcp_estimator", args, &declared, extra)?;
    let geometry = Geometry::from_params(&ctx.params)?;
    let busy = BUSY_POLL
        .f64(&ctx.params)
        .map_err(super::context::bad_param)?;
    // Bounded where read: an invalid priority is bad configuration (exit 2), not a node that
    // says so in its log and runs at normal priority.
    let rt_priority = PRIORITY
        .u64(&ctx.params)
        .map_err(super::context::bad_param)?;
    let mut input = DriveInput::open(&ctx)?;
    let mut parameters = ParameterFollower::open(&ctx)?;
    let estimates = ctx.publisher(&topic::TCP_ESTIMATE)?;
    let mut views = TcpViews::open(&ctx)?;
    let dds = matches!(ctx.output, Backend::Dds | Backend::Both);
    let mut live = input.start_params(&ctx, specs(dds), |p| configure(p).map(|_| ()))?;
    let diagnostics = ctx.publisher(&topic::DIAGNOSTICS)?;
    let services = super::calibration_services::CalibrationServices::open(&ctx)?;
    let mut lifecycle = Lifecycle::open(&ctx, super::lifecycle::start(args))?;
    ctx.started(format!(
        "estimating with {} ({}), publishing on {:?}, subscribing on {:?}",
        geometry.source, geometry.model, ctx.output, ctx.input
    ));
    let mut est = Estimator::new(geometry);
    // After the ports exist (their shared memory is mapped, then locked).
    // Without the privilege the node still estimates, at normal priority, and says so.
    match super::realtime::set_fifo(rt_priority) {
        Ok(Some(note)) => ctx.log(format!("real-time: {note}")),
        Ok(None) => {}
        Err(e) => ctx.log(format!(
            "real-time scheduling not set, running at normal priority: {e}"
        )),
    }
    // Between samples the node sleeps until the publisher's wake-up; the 20 ms bound keeps
    // the parameter checks and reports going when no sample comes.
    let mut idle = Idle::new(
        Duration::from_secs_f64(seconds_from_ms(busy)),
        Duration::from_millis(20),
    );
    let mut report = Every::new(ctx.diagnostics_period()?);
    let mut lost_reported = 0;
    while !super::shutdown::requested() {
        lifecycle.serve(&ctx, || {
            reconfigure(args, &ctx, &declared, &mut est, views.as_mut())
        });
        if let Some(g) = parameters.poll(&ctx, est.geometry())? {
            est.set_geometry(g);
        }
        if let Some(set) = input.set_before_state(&mut live) {
            apply_set(&ctx, set, (&mut est, views.as_mut(), &mut input))?;
        }
        if let Some(state) = input.next(&ctx)? {
            // an inactive node takes its input (no backlog at activation) and publishes
            // nothing, as rclcpp's lifecycle publishers
            if let Some(e) = lifecycle.active().then(|| est.estimate(&state)).flatten() {
                estimates.publish(&e)?;
                if let Some(v) = views.as_mut() {
                    v.offer(&e)?;
                }
            }
            idle.worked();
        } else {
            // Between samples only: a set costs the sample path nothing.
            if let Some(set) = live.poll() {
                apply_set(&ctx, set, (&mut est, views.as_mut(), &mut input))?;
            }
            if let Some(g) = services.as_ref().and_then(|s| s.poll(&ctx, est.geometry())) {
                est.set_geometry(g);
            }
            if report.due() {
                let mut status = est.status(&ctx.status_name);
                input.annotate(&mut status);
                diagnostics.publish(&ctx.diagnostics(status))?;
                // A loss is logged once per report, not per gap (a stall loses in bursts).
                if est.input.lost > lost_reported {
                    lost_reported = est.input.lost;
                    ctx.log(format!("WARN: {}", est.input.summary().unwrap_or_default()));
                }
            }
            input.wait(&idle)?;
        }
    }
    ctx.log("stopping");
    Ok(())
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;
    use crate::units::{m_from_mm, mm_from_m};
    use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE, FOLLOWERS_23};
    use rpkm_core::geometry::{fgm, igm};
    use rpkm_core::params::Params;

    fn geometry() -> Geometry {
        Geometry {
            params: Params::nominal(),
            model: Model::M29,
            stiffness: Stiffness::default(),
            source: "test".into(),
            effects: crate::node::effects::NodeEffects::default(),
        }
    }

    fn state(q_mm: [f64; 4], seq: u64) -> ActuatorState {
        ActuatorState {
            seq,
            position: q_mm.map(m_from_mm),
            ..Default::default()
        }
    }

    #[test]
    fn estimate_matches_the_core_and_warm_starts() -> Result<(), Box<dyn std::error::Error>> {
        let p = Params::nominal();
        let mut q = igm(&p, Model::M29, 20.0, 1650.0)?.q();
        q[2] += 0.05; // a little preload on q3
        let mut est = Estimator::new(geometry());
        let first = est.estimate(&state(q, 7)).ok_or("no estimate")?;
        let truth = fegm(
            &p,
            &Stiffness::default(),
            q.map(|v| mm_from_m(m_from_mm(v))),
            ALL_ACTIVE,
        )?;
        assert_eq!(first.seq, 7);
        assert!(first.converged);
        assert_eq!(
            (first.outcome, first.reason),
            (TcpEstimate::OUTCOME_OK, TcpEstimate::REASON_NONE)
        );
        assert!((first.x - m_from_mm(truth.x)).abs() < 1e-12);
        assert!((first.y - m_from_mm(truth.y)).abs() < 1e-12);
        for i in 0..4 {
            assert!((first.drive_forces[i] - truth.drive_force[i]).abs() < 1e-6);
        }
        // rod elongation = force / stiffness
        for i in 0..5 {
            let expect = m_from_mm(truth.rod_force[i] / Stiffness::default().rod[i]);
            assert!(
                (first.loop_residuals[i] - expect).abs() < 1e-12,
                "rod {}",
                i + 1
            );
        }
        let second = est.estimate(&state(q, 8)).ok_or("no estimate")?;
        assert!(second.iterations < first.iterations, "warm start");
        assert_eq!(est.counts.cold_starts, 1);
        Ok(())
    }

    #[test]
    fn unreachable_state_gives_no_estimate_and_is_counted() {
        let mut est = Estimator::new(geometry());
        assert!(est.estimate(&state([1e5, 0.0, 0.0, -1e5], 1)).is_none());
        assert_eq!(est.counts.unsolved, 1);
        assert_eq!(est.status("e").level, DiagnosticStatus::WARN);
    }

    /// Distance of an estimate from the rigid model of its own encoders, mm.
    fn off_rigid(e: &TcpEstimate, q_mm: [f64; 4]) -> Result<f64, Box<dyn std::error::Error>> {
        let r = fgm(&Params::nominal(), Model::M29, q_mm[0], q_mm[3])?;
        Ok((mm_from_m(e.x) - r.x()).hypot(mm_from_m(e.y) - r.y()))
    }

    #[test]
    fn a_1_m_jump_is_solved_cold_and_stays_plausible() -> Result<(), Box<dyn std::error::Error>> {
        // Poses 76 and 77 of bags/demo/campaign.csv: the last laser-tracker pose, then the
        // first self-calibration pose 1 m away, where the warm solve turns the platform over.
        let a = [
            1_719.817_052_762_383_1,
            1_440.992_148_889_116_8,
            -44.118_952_409_150_77,
            -319.817_052_762_383_1,
        ];
        let b = [
            2_442.309_874_518_249_7,
            2_719.006_545_410_108,
            678.643_558_330_334_1,
            957.690_125_481_750_1,
        ];
        let mut est = Estimator::new(geometry());
        let mut s = state(a, 1);
        s.follower = FOLLOWERS_23;
        est.estimate(&s).ok_or("no estimate")?;
        s = state(b, 2);
        s.follower = FOLLOWERS_23;
        let e = est.estimate(&s).ok_or("no estimate")?;
        assert!(e.converged);
        assert_eq!(e.outcome, TcpEstimate::OUTCOME_WARM_REJECTED_COLD_OK);
        assert_eq!(e.reason, TcpEstimate::REASON_PLATFORM_ANGLE);
        assert!(off_rigid(&e, b)? < 1e-6, "{} mm", off_rigid(&e, b)?);
        assert!(e.psi.abs() < 0.01);
        assert_eq!(est.counts.warm_rejected, 1, "{:?}", est.counts);
        assert_eq!(est.last_warm_rejection, Some(Reason::PlatformAngle));
        assert_eq!(est.counts.rigid_fallbacks, 0);
        let st = est.status("e");
        assert_eq!(st.level, DiagnosticStatus::OK, "{}", st.message);
        Ok(())
    }

    #[test]
    fn implausible_states_fall_back_flagged_and_escalate() -> Result<(), Box<dyn std::error::Error>>
    {
        // q3 50 mm off its compatible position: the elastic model answers with forces 100x
        // the drives', which no machine holds; the rigid model of (q1, q4) is published.
        let p = Params::nominal();
        let good = igm(&p, Model::M29, 20.0, 1650.0)?.q();
        let mut bad = good;
        bad[2] += 50.0;
        let mut est = Estimator::new(geometry());
        let e = est.estimate(&state(bad, 1)).ok_or("no estimate")?;
        assert!(!e.converged);
        assert_eq!(e.outcome, TcpEstimate::OUTCOME_RIGID_FALLBACK);
        assert_eq!(e.iterations, 0);
        assert_eq!(e.drive_forces, [0.0; 4]);
        assert!(off_rigid(&e, bad)? < 1e-9);
        assert_eq!(est.counts.implausible, 1);
        assert_eq!(
            est.counts.by_reason.iter().sum::<u64>(),
            1,
            "{:?}",
            est.counts
        );
        let reason = match &est.last_error {
            Some(ElasticError::Implausible(v)) => v.reason,
            other => return Err(format!("not an implausible solve: {other:?}").into()),
        };
        let st = est.status("e");
        assert_eq!(st.level, DiagnosticStatus::WARN, "{}", st.message);
        let value = |st: &DiagnosticStatus, k: &str| {
            st.values
                .iter()
                .find(|v| v.key == k)
                .map(|v| v.value.clone())
        };
        assert_eq!(value(&st, "last_reason").as_deref(), Some(reason.as_str()));
        assert_eq!(e.reason, reason.code(), "the message names the same check");
        assert_ne!(e.reason, TcpEstimate::REASON_NONE);
        for seq in 2..=ERROR_AFTER_CONSECUTIVE {
            let e = est.estimate(&state(bad, seq)).ok_or("no estimate")?;
            assert!(!e.converged);
        }
        assert_eq!(est.status("e").level, DiagnosticStatus::ERROR);
        let e = est.estimate(&state(good, 100)).ok_or("no estimate")?;
        assert!(e.converged);
        assert_eq!(est.counts.consecutive_failures, 0);
        assert_eq!(
            est.status("e").level,
            DiagnosticStatus::WARN,
            "cumulative warning"
        );
        Ok(())
    }

    #[test]
    fn a_gap_in_the_input_is_a_warning_with_its_size() -> Result<(), Box<dyn std::error::Error>> {
        let q = igm(&Params::nominal(), Model::M29, 0.0, 1700.0)?.q();
        let mut est = Estimator::new(geometry());
        for seq in [1, 2, 767] {
            est.estimate(&state(q, seq)).ok_or("no estimate")?;
        }
        let st = est.status("e");
        assert_eq!(st.level, DiagnosticStatus::WARN, "{}", st.message);
        assert!(
            st.message
                .ends_with("input: 764 actuator states lost in 1 gaps (largest 764)"),
            "{}",
            st.message
        );
        let lost = st.values.iter().find(|v| v.key == "input_lost");
        assert_eq!(lost.map(|v| v.value.as_str()), Some("764"));
        Ok(())
    }

    #[test]
    fn message_reason_codes_are_the_cores() {
        let msg = [
            (Reason::NotConverged, TcpEstimate::REASON_NOT_CONVERGED),
            (Reason::LoopClosure, TcpEstimate::REASON_LOOP_CLOSURE),
            (Reason::ForceBalance, TcpEstimate::REASON_FORCE_BALANCE),
            (Reason::ForceLimit, TcpEstimate::REASON_FORCE_LIMIT),
            (Reason::PlatformAngle, TcpEstimate::REASON_PLATFORM_ANGLE),
            (Reason::FarFromRigid, TcpEstimate::REASON_FAR_FROM_RIGID),
        ];
        assert_eq!(msg.len(), Reason::ALL.len());
        for (r, code) in msg {
            assert_eq!(r.code(), code, "{r}");
        }
    }

    #[test]
    fn psi_is_published_wrapped() -> Result<(), Box<dyn std::error::Error>> {
        let p = Params::nominal();
        let q = igm(&p, Model::M29, 0.0, 1700.0)?.q();
        let mut est = Estimator::new(geometry());
        est.estimate(&state(q, 1)).ok_or("no estimate")?;
        // A warm start a whole turn away (what the issue saw as ψ = −6.2832 rad).
        if let Some(prev) = est.previous.as_mut() {
            prev.eq.psi -= std::f64::consts::TAU;
        }
        let e = est.estimate(&state(q, 2)).ok_or("no estimate")?;
        assert!(e.psi.abs() < 1e-6, "ψ {}", e.psi);
        Ok(())
    }

    /// Forces not measured (NaN) change no estimate; an effect that reads one leaves the
    /// state unestimated, counted and named.
    #[test]
    fn unmeasured_forces_are_not_read() -> Result<(), Box<dyn std::error::Error>> {
        let mut q = igm(&Params::nominal(), Model::M29, 20.0, 1650.0)?.q();
        q[2] += 0.05;
        let with = Estimator::new(geometry()).estimate(&state(q, 1));
        let mut without = state(q, 1);
        without.force = [f64::NAN; 4];
        let mut est = Estimator::new(geometry());
        let e = est.estimate(&without).ok_or("no estimate")?;
        assert_eq!(Some(e), with, "bit for bit");
        let file = crate::effects_file::parse(
            "effects:\n  - name: drive_compliance_q1\n    summary: s\n    \
             params: {c: {unit: mm, prior: 0.01}}\n    dq1: \"c * f1 / 1000\"\n",
            "compliance.yaml",
            &[],
        )?;
        let mut g = geometry();
        g.effects = crate::node::effects::NodeEffects::known(Some(file));
        let msg = rpkm_msgs::Parameters {
            model: 29,
            active_effects: vec!["drive_compliance_q1".into()],
            effect_parameter_names: vec!["drive_compliance_q1.c".into()],
            effect_parameter_values: vec![0.01e-3],
            ..Default::default()
        };
        est.set_geometry(g.updated(&msg)?);
        assert!(est.estimate(&without).is_none());
        assert_eq!(est.counts.forces_not_measured, 1);
        let st = est.status("e");
        assert_eq!(st.level, DiagnosticStatus::WARN);
        assert!(
            st.message.ends_with(
                "1 states not estimated: effect `drive_compliance_q1` reads f1, which the \
                 drive state does not measure (NaN)"
            ),
            "{}",
            st.message
        );
        Ok(())
    }
}
