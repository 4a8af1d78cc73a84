//! Drive states straight from a ros2_control cell, no bridge: the joint_state_broadcaster's
//! `sensor_msgs/JointState` (parameter `joint_states_topic`, default `/joint_states`) read as
//! ActuatorStates, and the cell's `sensor_msgs/Temperature` thermometers (`temperatures:
//! {covariate: topic}`) attached to every state as its covariates.
//!
//! The four drives are picked by name (`joint_names`) wherever the message lists them; other
//! joints are ignored. Positions are m as on the wire; efforts become rpkm's drive forces
//! (positive towards larger q) through `effort_sign` per drive. Which drives follow is
//! parameter `followers`, settable while the node runs. A message that cannot be read is
//! refused and counted per joint on /diagnostics ([`convert::JointReject`]); a thermometer
//! silent longer than `temperature_timeout_s` makes its covariate NaN ("not measured") and
//! is named on /diagnostics ([`thermometers`]).
//!
//! Ingest reads this as its `joint_states` source; the estimator and the preload monitor read
//! it directly with `source: joint_states` (`super::inputs::DriveInput`).

mod config;
mod convert;
mod thermometers;

use std::time::Instant;

use rpkm_core::campaign::followers_words;
use rpkm_msgs::{ActuatorState, DiagnosticStatus, JointState, KeyValue, Temperature};
use rpkm_transport::names::intern;
use rpkm_transport::{Backend, Qos, Subscriber, Topic};

pub use config::{followers, JointConfig, Thermometer, JOINT_NAMES, JOINT_STATES_TOPIC, PARAMS};
pub use convert::{drive_state, JointReject};
pub use thermometers::{ThermometerChange, Thermometers};

use super::context::{bad_param, Idle, NodeContext};
use super::params::NodeParams;

/// Depth of the JointState reader: a second of a 1 kHz broadcaster.
const JOINT_STATES_DEPTH: usize = 1024;
/// Depth of a thermometer's reader: only its latest reading counts.
const TEMPERATURE_DEPTH: usize = 16;

/// JointStates refused, per drive joint and why.
#[derive(Debug, Clone, Default)]
struct Refusals {
    missing: [u64; 4],
    repeated: [u64; 4],
    non_finite: [u64; 4],
    unequal_arrays: u64,
    last: Option<String>,
    total: u64,
    at_last_report: u64,
}

impl Refusals {
    fn count(&mut self, r: &JointReject, joints: &[String; 4]) {
        let drive = r
            .joint()
            .and_then(|j| joints.iter().position(|n| n == j))
            .unwrap_or(0);
        match r {
            JointReject::MissingJoint { .. } => self.missing[drive] += 1,
            JointReject::RepeatedJoint { .. } => self.repeated[drive] += 1,
            JointReject::NonFinite { .. } => self.non_finite[drive] += 1,
            JointReject::UnequalArrays { .. } => self.unequal_arrays += 1,
        }
        self.total += 1;
    }
}

/// Whether the JointState refusals set the level of the status a [`JointInput`] annotates,
/// or the node counts them itself (ingest, through its reject tally).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefusalLevel {
    /// WARN while refusals occur, named in the message.
    Raise,
    /// Values only.
    ValuesOnly,
}

/// The JointState and Temperature readers of a node and what they were told.
pub struct JointInput {
    config: JointConfig,
    topic: &'static str,
    joint_states: Subscriber<JointState>,
    temperatures: Vec<Subscriber<Temperature>>,
    readings: Thermometers,
    received: u64,
    refusals: Refusals,
    /// When the last JointState arrived (the input's opening before the first).
    last_received: Instant,
    /// Whether the input is quiet, as last logged.
    quiet: bool,
    /// The node's name, for its log lines.
    node: String,
}

impl JointInput {
    /// Subscribes on DDS to the JointState topic (reliable unless `joint_states_qos` says
    /// best_effort: a reliable reader matches the broadcaster's default, SystemDefaultsQoS)
    /// and to each thermometer (best effort: matches every writer, and only the latest
    /// reading counts).
    pub fn open(ctx: &NodeContext, config: JointConfig) -> anyhow::Result<Self> {
        let topic = intern(config.topic.clone());
        let qos = if config.reliable {
            Qos::reliable(JOINT_STATES_DEPTH)
        } else {
            Qos::best_effort(JOINT_STATES_DEPTH)
        };
        let joint_states = ctx
            .transport
            .subscriber_on(&Topic::new(topic, qos), Backend::Dds)?;
        let temperatures = config
            .thermometers
            .iter()
            .map(|t| {
                let topic =
                    Topic::new(intern(t.topic.clone()), Qos::best_effort(TEMPERATURE_DEPTH));
                ctx.transport.subscriber_on(&topic, Backend::Dds)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let readings = Thermometers::new(config.thermometers.clone(), config.timeout);
        Ok(Self {
            config,
            topic,
            joint_states,
            temperatures,
            readings,
            received: 0,
            refusals: Refusals::default(),
            last_received: Instant::now(),
            quiet: false,
            node: ctx.name.clone(),
        })
    }

    /// The JointState topic.
    pub fn topic(&self) -> &'static str {
        self.topic
    }

    /// The covariate names of the states, in order.
    pub fn covariate_names(&self) -> Vec<String> {
        self.config.covariate_names()
    }

    /// The drives in follower mode.
    pub fn followers(&self) -> [bool; 4] {
        self.config.followers
    }

    /// Takes `followers` of parameter set `p` (as the parameter services accepted it) for the
    /// states read from now on; a change is logged with the seq of the first state it
    /// applies to, `next_seq`.
    pub fn take_followers(
        &mut self,
        ctx: &NodeContext,
        p: &NodeParams,
        next_seq: u64,
    ) -> anyhow::Result<()> {
        let new = followers(p).map_err(bad_param)?;
        let old = self.config.followers;
        if new != old {
            self.config.followers = new;
            ctx.log(format!(
                "followers {} -> {} from seq {next_seq} on (set through the parameter services)",
                followers_words(old),
                followers_words(new),
            ));
        }
        Ok(())
    }

    /// Takes the readings that arrived; a refused one is logged.
    fn take_temperatures(&mut self, ctx: &NodeContext, now: Instant) -> anyhow::Result<()> {
        for (i, sub) in self.temperatures.iter().enumerate() {
            while let Some(t) = sub.try_recv()? {
                if let Err(why) = self.readings.reading(i, t.temperature, now) {
                    ctx.log(format!("WARN: rejected: {why}"));
                }
            }
        }
        Ok(())
    }

    /// The next drive state (no seq: the node numbers what it publishes), its covariates
    /// the thermometers' latest readings, or why the next JointState gives none; `None` when
    /// no JointState is queued. Thermometers that went quiet or spoke again are logged.
    pub fn next(
        &mut self,
        ctx: &NodeContext,
    ) -> anyhow::Result<Option<Result<ActuatorState, JointReject>>> {
        let now = Instant::now();
        self.take_temperatures(ctx, now)?;
        let Some(js) = self.joint_states.try_recv()? else {
            return Ok(None);
        };
        self.received += 1;
        self.last_received = now;
        let mut state = match drive_state(&js, &self.config) {
            Ok(s) => s,
            Err(r) => {
                self.refusals.count(&r, &self.config.joints);
                self.refusals.last = Some(format!("{}: {r}", self.topic));
                return Ok(Some(Err(r)));
            }
        };
        let n = self.readings.list().len();
        for change in self.readings.covariates(now, &mut state.covariates[..n]) {
            ctx.log(change);
        }
        // at most MAX_COVARIATES thermometers (JointConfig)
        state.covariate_count = u8::try_from(n).unwrap_or(u8::MAX);
        Ok(Some(Ok(state)))
    }

    /// Waits for the next JointState as `idle` says.
    pub fn wait(&self, idle: &Idle) -> anyhow::Result<()> {
        Ok(idle.wait_for(&self.joint_states)?)
    }

    /// `joint states quiet for 1.2 s (/joint_states)` while no JointState came for
    /// `joint_states_timeout_s`; the log says when the input went quiet and spoke again.
    fn quiet_note(&mut self, now: Instant) -> Option<String> {
        let silent = now.duration_since(self.last_received);
        let quiet = silent >= self.config.quiet_after;
        if quiet != self.quiet {
            self.quiet = quiet;
            let line = if quiet {
                format!(
                    "WARN: joint states quiet: no JointState on {} for {:.1} s",
                    self.topic,
                    silent.as_secs_f64()
                )
            } else {
                format!("joint states on {} again", self.topic)
            };
            crate::node::context::log_line(&self.node, line);
        }
        quiet.then(|| {
            format!(
                "joint states quiet for {:.1} s ({})",
                silent.as_secs_f64(),
                self.topic
            )
        })
    }

    /// Adds the input's values to `status`: what was received and refused per joint, the
    /// followers, each thermometer; WARN while a thermometer is quiet (named in the message),
    /// and with [`RefusalLevel::Raise`] while JointStates are refused.
    pub fn annotate(&mut self, status: &mut DiagnosticStatus, refusals: RefusalLevel) {
        let now = Instant::now();
        let mut notes: Vec<String> = self.quiet_note(now).into_iter().collect();
        let r = &mut self.refusals;
        let fresh = r.total - r.at_last_report;
        r.at_last_report = r.total;
        if refusals == RefusalLevel::Raise && fresh > 0 {
            notes.push(format!(
                "{fresh} JointState messages refused since the last report; last: {}",
                r.last.as_deref().unwrap_or("")
            ));
        }
        let incompatible = self.joint_states.incompatible_publishers();
        if !incompatible.is_empty() {
            notes.push(format!(
                "{} publisher(s) of {} not matched, incompatible QoS (set joint_states_qos): {}",
                incompatible.len(),
                self.topic,
                incompatible.join("; ")
            ));
        }
        if let Some(quiet) = self.readings.quiet_summary(now) {
            notes.push(quiet);
        }
        if !notes.is_empty() {
            status.level = status.level.max(DiagnosticStatus::WARN);
            status.message = format!("{}; {}", status.message, notes.join("; "));
        }
        let mut values = vec![
            ("joint_states_topic".to_owned(), self.topic.to_owned()),
            ("joint_states_received".into(), self.received.to_string()),
            (
                "joint_states_incompatible_qos".into(),
                incompatible.len().to_string(),
            ),
            ("joint_states_quiet".into(), self.quiet.to_string()),
            ("followers".into(), self.config.followers_text()),
            ("joint_unequal_arrays".into(), r.unequal_arrays.to_string()),
        ];
        for (d, joint) in self.config.joints.iter().enumerate() {
            values.push((format!("joint_missing.{joint}"), r.missing[d].to_string()));
            values.push((format!("joint_repeated.{joint}"), r.repeated[d].to_string()));
            values.push((
                format!("joint_non_finite.{joint}"),
                r.non_finite[d].to_string(),
            ));
        }
        values.push((
            "joint_last_refusal".into(),
            r.last.clone().unwrap_or_default(),
        ));
        values.extend(self.readings.values(now));
        status.values.extend(
            values
                .into_iter()
                .map(|(key, value)| KeyValue { key, value }),
        );
    }
}
