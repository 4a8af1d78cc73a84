//! What the servo-rate nodes (`tcp_estimator`, `preload_monitor`) share about their inputs:
//! where their drive states come from ([`DriveInput`]: ingest's ActuatorState, or the cell's
//! JointState directly), gaps in the actuator stream ([`SeqGaps`]), following new Parameters
//! while they run ([`ParameterFollower`]) and the model's inputs of a drive state under the
//! geometry's calibrated effects ([`StreamMotion`]).

use std::time::Duration;

use rpkm_core::campaign::Motion;
use rpkm_core::effects::LiveState;
use rpkm_core::params::Params;
use rpkm_msgs::{ActuatorState, DiagnosticStatus, Parameters};
use rpkm_transport::{topic, Backend, Subscriber};

use super::context::{bad_param, CommonArgs, Every, Idle, NodeContext};
use super::declare::{self, ParamDefault, ParamSpec};
use super::geometry::Geometry;
use super::joint_input::{self, JointConfig, JointInput, RefusalLevel};
use super::live::LiveParams;
use super::params::NodeParams;
use crate::campaign_bag::seconds_from_stamp;
use crate::error::bad_input;
use crate::units::drive_positions_mm;

/// Parameter `source` of a servo-rate node: ingest's ActuatorState (default).
const ACTUATOR_STATE: &str = "actuator_state";
/// Parameter `source` of a servo-rate node: the cell's JointState, on DDS.
const JOINT_STATES: &str = "joint_states";

/// Parameter `source` of a servo-rate node.
pub const SOURCE: ParamSpec = ParamSpec::fixed(
    "source",
    ParamDefault::Str(ACTUATOR_STATE),
    "drive states: actuator_state (ingest's) or joint_states (the cell's JointState, DDS)",
);

/// `specs` with the drive input's: `source` and the JointState input's.
pub fn with_drive_input(mut specs: Vec<ParamSpec>) -> Vec<ParamSpec> {
    specs.push(SOURCE);
    specs.extend(joint_input::PARAMS);
    specs
}

/// The backend a node of kind `kind` subscribes on besides its input: DDS with `source:
/// joint_states` (the cell's topics are DDS topics), else none.
pub fn extra_backend(args: &CommonArgs, kind: &str) -> anyhow::Result<Option<Backend>> {
    let p = args.identity(kind)?.params().map_err(bad_param)?;
    let source = SOURCE.string(&p).map_err(bad_param)?;
    Ok((source == JOINT_STATES).then_some(Backend::Dds))
}

/// Where a servo-rate node's drive states come from.
pub enum DriveInput {
    /// Ingest's ActuatorState on the node's input backend.
    Actuator(Subscriber<ActuatorState>),
    /// ros2_control's JointState and the cell's thermometers on DDS, numbered here.
    Joints {
        /// The readers.
        input: Box<JointInput>,
        /// The seq of the last state.
        seq: u64,
    },
}

impl DriveInput {
    /// The input parameter `source` names: `actuator_state` (default) or `joint_states`.
    pub fn open(ctx: &NodeContext) -> anyhow::Result<Self> {
        let p = &ctx.params;
        // checked whatever the source: a bad value is bad before the cell switches to it
        let config = JointConfig::from_params(p).map_err(bad_param)?;
        match SOURCE.string(p).map_err(bad_param)?.as_str() {
            ACTUATOR_STATE => Ok(Self::Actuator(ctx.subscriber(&topic::ACTUATOR_STATE)?)),
            JOINT_STATES => Ok(Self::Joints {
                input: Box::new(JointInput::open(ctx, config)?),
                seq: 0,
            }),
            other => Err(bad_input(format!(
                "{}/source: expected actuator_state or joint_states, found {other:?}",
                p.origin("source")
                    .map(ToString::to_string)
                    .unwrap_or_default()
            ))),
        }
    }

    /// The input's parameters on the node's parameter services.
    pub fn specs(&self) -> Vec<ParamSpec> {
        match self {
            Self::Joints { .. } => declare::served(&[&[SOURCE], &joint_input::PARAMS]),
            Self::Actuator(_) => vec![SOURCE],
        }
    }

    /// The node's parameter services with `specs` and the input's; a set passes
    /// `configure` (the node's check) and the input's check of `followers`.
    pub fn start_params(
        &self,
        ctx: &NodeContext,
        mut specs: Vec<ParamSpec>,
        configure: impl Fn(&NodeParams) -> anyhow::Result<()> + Send + 'static,
    ) -> anyhow::Result<LiveParams> {
        specs.extend(self.specs());
        LiveParams::start(ctx, &specs, move |p| {
            joint_input::followers(p).map_err(bad_param)?;
            configure(p)
        })
    }

    /// The parameter set to apply before the next state: with the JointState input every
    /// accepted set is taken before each state (its `followers` apply from the next state
    /// on); else `None`, and the node takes sets between samples.
    pub fn set_before_state(&self, live: &mut LiveParams) -> Option<(NodeParams, Vec<String>)> {
        match self {
            Self::Joints { .. } => live.poll_now(),
            Self::Actuator(_) => None,
        }
    }

    /// Applies a parameter set the services accepted: the followers of the JointState
    /// input, from the next state on (logged).
    pub fn configure(&mut self, ctx: &NodeContext, p: &NodeParams) -> anyhow::Result<()> {
        match self {
            Self::Actuator(_) => Ok(()),
            Self::Joints { input, seq } => input.take_followers(ctx, p, *seq + 1),
        }
    }

    /// The next drive state, `None` when none is queued. A JointState that cannot be read is
    /// logged and counted (on /diagnostics through [`Self::annotate`]), never passed on.
    pub fn next(&mut self, ctx: &NodeContext) -> anyhow::Result<Option<ActuatorState>> {
        match self {
            Self::Actuator(sub) => Ok(sub.try_recv()?),
            Self::Joints { input, seq } => loop {
                match input.next(ctx)? {
                    None => return Ok(None),
                    Some(Ok(mut state)) => {
                        *seq += 1;
                        state.seq = *seq;
                        return Ok(Some(state));
                    }
                    Some(Err(r)) => ctx.log(format!("WARN: rejected: {}: {r}", input.topic())),
                }
            },
        }
    }

    /// Waits for the next state as `idle` says.
    pub fn wait(&self, idle: &Idle) -> anyhow::Result<()> {
        match self {
            Self::Actuator(sub) => Ok(idle.wait_for(sub)?),
            Self::Joints { input, .. } => input.wait(idle),
        }
    }

    /// Adds the JointState input's values and warnings to the node's status.
    pub fn annotate(&mut self, status: &mut DiagnosticStatus) {
        if let Self::Joints { input, .. } = self {
            input.annotate(status, RefusalLevel::Raise);
        }
    }
}

/// How the carriers of one actuator stream moved (the direction of each one's last move, its
/// travel since its last reversal, the time since the stream's first state: the covariates a
/// calibrated effect may read, by the definition of the campaign's own), followed at every
/// state whether an effect reads them or not.
#[derive(Debug, Clone, Copy, Default)]
pub struct StreamMotion {
    motion: Motion,
}

impl StreamMotion {
    /// The parameters and carrier positions (mm, rad) the model is evaluated at for state
    /// `s` under the calibrated effects of `g` (its own parameters and the encoders without
    /// any); `Err` when an effect reads a drive force the state does not measure (NaN).
    pub fn model_inputs(
        &mut self,
        g: &mut Geometry,
        s: &ActuatorState,
    ) -> Result<(Params, [f64; 4]), UnmeasuredForce> {
        let q = drive_positions_mm(s);
        let t = seconds_from_stamp(s.stamp);
        // followed at every state, evaluated or not
        let motion = self.motion.next(q, t);
        if let Some((effect, drive)) = g.effects.unmeasured_force(&s.force) {
            return Err(UnmeasuredForce {
                effect: effect.to_owned(),
                drive,
            });
        }
        Ok(g.effects.apply(
            &g.params,
            &LiveState {
                q,
                f: s.force,
                t,
                motion,
            },
        ))
    }
}

/// A drive state the calibrated effects cannot be evaluated at: an effect reads a drive
/// force the state does not measure (NaN: a cell without force sensing). The model without
/// the effect is not this machine's, so the state gets no model answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnmeasuredForce {
    /// The effect.
    pub effect: String,
    /// The drive, 0..=3.
    pub drive: usize,
}

impl std::fmt::Display for UnmeasuredForce {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "effect `{}` reads f{}, which the drive state does not measure (NaN)",
            self.effect,
            self.drive + 1
        )
    }
}

/// Gaps in a stream whose `seq` counts up by one per sample (ingest's ActuatorState): the
/// actuator topic is best effort, so a subscriber that falls more than its queue behind
/// loses the oldest samples, and this is where that shows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SeqGaps {
    last: Option<u64>,
    /// Gaps seen (each one or more samples missing).
    pub gaps: u64,
    /// Samples missing in all gaps.
    pub lost: u64,
    /// The largest gap, samples.
    pub largest: u64,
    /// Times `seq` went back or repeated (the publisher restarted): not a gap.
    pub restarts: u64,
}

impl SeqGaps {
    /// Takes the `seq` of the next sample received; returns how many samples are missing
    /// before it (0: none).
    pub fn next(&mut self, seq: u64) -> u64 {
        let missing = match self.last {
            Some(prev) if seq > prev => seq - prev - 1,
            Some(_) => {
                self.restarts += 1;
                0
            }
            None => 0,
        };
        self.last = Some(seq);
        if missing > 0 {
            self.gaps += 1;
            self.lost = self.lost.saturating_add(missing);
            self.largest = self.largest.max(missing);
        }
        missing
    }

    /// The counters as /diagnostics values.
    pub fn values(&self) -> [(&'static str, String); 4] {
        [
            ("input_gaps", self.gaps.to_string()),
            ("input_lost", self.lost.to_string()),
            ("largest_input_gap", self.largest.to_string()),
            ("input_restarts", self.restarts.to_string()),
        ]
    }

    /// One line for people, or `None` while nothing was lost.
    pub fn summary(&self) -> Option<String> {
        (self.lost > 0).then(|| {
            format!(
                "{} actuator states lost in {} gaps (largest {})",
                self.lost, self.gaps, self.largest
            )
        })
    }
}

/// How often a following node looks for new Parameters: a calibration result is rare, and
/// the check must cost the servo loop nothing.
const PARAMETER_CHECK: Duration = Duration::from_millis(20);

/// Follows `/rpkm/parameters` when the node's `follow_parameters` (default true) says so.
pub struct ParameterFollower {
    parameters: Option<Subscriber<Parameters>>,
    check: Every,
}

impl ParameterFollower {
    /// Reads `follow_parameters` and subscribes when it is true.
    pub fn open(ctx: &NodeContext) -> anyhow::Result<Self> {
        let follow = crate::node::geometry::FOLLOW_PARAMETERS
            .bool(&ctx.params)
            .map_err(bad_param)?;
        let parameters = if follow {
            Some(ctx.subscriber(&topic::PARAMETERS)?)
        } else {
            None
        };
        Ok(Self {
            parameters,
            check: Every::new(PARAMETER_CHECK),
        })
    }

    /// The geometry of a Parameters message received since the last check, built on
    /// `current` (logged); a message that does not fit the node's model is logged and
    /// ignored. At most one look per [`PARAMETER_CHECK`].
    pub fn poll(
        &mut self,
        ctx: &NodeContext,
        current: &Geometry,
    ) -> anyhow::Result<Option<Geometry>> {
        let Some(sub) = &self.parameters else {
            return Ok(None);
        };
        if !self.check.due() {
            return Ok(None);
        }
        let Some(msg) = sub.try_recv()? else {
            return Ok(None);
        };
        match current.updated(&msg) {
            Ok(g) => {
                ctx.log(format!("parameters updated from {}", g.source));
                Ok(Some(g))
            }
            Err(e) => {
                ctx.log(format!("ignoring parameters: {e}"));
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_are_counted_with_their_size_and_restarts_are_not_gaps() {
        let mut g = SeqGaps::default();
        for seq in [1, 2, 3] {
            assert_eq!(g.next(seq), 0);
        }
        assert_eq!(g.next(8), 4, "4, 5, 6, 7 missing");
        assert_eq!(g.next(9), 0);
        assert_eq!(g.next(11), 1);
        assert_eq!((g.gaps, g.lost, g.largest), (2, 5, 4));
        assert_eq!(g.next(1), 0, "the publisher restarted");
        assert_eq!(g.next(2), 0);
        assert_eq!((g.gaps, g.lost, g.restarts), (2, 5, 1));
        assert_eq!(
            g.summary().as_deref(),
            Some("5 actuator states lost in 2 gaps (largest 4)")
        );
        assert_eq!(SeqGaps::default().summary(), None);
    }
}
