//! `~/calibrate` (`rpkm_msgs/action/Calibrate`) of the calibrator: a cell controller asks for
//! a calibration and waits for its result, with feedback at every Levenberg-Marquardt
//! iteration and noise round, and may cancel it. On DDS only (actions are ROS 2's), served
//! from the node's loop ([`rpkm_transport::dds_actions`]); the calibrator executes one goal at
//! a time, in its loop (`calibrator::run`), and only while active (a goal to an inactive
//! node is refused).
//!
//! This module is the action's side of a goal: [`Running::observe`] is the core's progress
//! observer (`calib::Request::progress`): it turns each iteration and round into feedback
//! and a cancel request into `Flow::Stop`, which the core ends as
//! `CalibrationError::Cancelled` at its next iteration.
//!
//! ```text
//! ros2 action send_goal /rpkm/calibrator/calibrate rpkm_msgs/action/Calibrate \
//!   "{campaign_file: /cell/campaign.csv}" --feedback
//! ```

use crate::units::{m_from_um, ms_from_seconds};
use std::cell::Cell;
use std::time::Instant;

use rpkm_core::calib::{Flow, Progress};
use rpkm_core::obs::Step;
use rpkm_core::variance::NoiseEstimate;
use rpkm_msgs::calibrate_action::{CalibrateFeedback, CalibrateGoal, CalibrateResult, CALIBRATE};
use rpkm_transport::dds_actions::{ActionServer, ActionType, GoalEnd, GoalHandle};

use super::context::NodeContext;

/// The action of one calibrator.
pub struct CalibrateAction {
    server: ActionServer<CalibrateGoal, CalibrateResult, CalibrateFeedback>,
}

impl CalibrateAction {
    /// The action of `ctx`'s node, when it is on DDS (`None` on iceoryx2 only).
    pub fn open(ctx: &NodeContext) -> anyhow::Result<Option<Self>> {
        let Some(dds) = ctx.transport.dds_node() else {
            return Ok(None);
        };
        let kind = ActionType {
            package: rpkm_msgs::PACKAGE,
            name: CALIBRATE,
        };
        Ok(Some(Self {
            server: dds.serve_action("calibrate", kind)?,
        }))
    }

    /// Answers the cancel and result requests waiting, and takes the next goal: accepted
    /// when the node is `active` (the caller executes it now), else refused and logged.
    pub fn next(&self, ctx: &NodeContext, active: bool) -> Option<(Running<'_>, CalibrateGoal)> {
        self.server.poll();
        let (goal, what) = self.server.next_goal()?;
        if !active {
            ctx.log(format!(
                "WARN: {}: goal refused: the node is not active (lifecycle activate first)",
                self.server.name()
            ));
            self.server.reject(goal);
            return None;
        }
        let handle = self.server.accept(goal);
        ctx.log(format!(
            "{}: goal {handle} accepted: {}",
            self.server.name(),
            describe(&what)
        ));
        Some((Running::new(self, handle), what))
    }
}

/// The goal as a log line.
fn describe(g: &CalibrateGoal) -> String {
    let campaign = if g.campaign_file.is_empty() {
        "the campaign collected so far".to_owned()
    } else {
        g.campaign_file.clone()
    };
    let noise = match g.noise {
        CalibrateGoal::NOISE_ESTIMATE => ", noise estimated",
        CalibrateGoal::NOISE_STATED => ", noise stated",
        _ => "",
    };
    format!(
        "{campaign}{}{}{}{noise}",
        if g.validation_file.is_empty() {
            String::new()
        } else {
            format!(", held out {}", g.validation_file)
        },
        if g.selection.is_empty() {
            String::new()
        } else {
            format!(", selection {}", g.selection)
        },
        if g.effects.is_empty() {
            String::new()
        } else {
            format!(", effects {}", g.effects)
        }
    )
}

/// A goal being executed: where its calibration stands, and when its cancel was seen.
pub struct Running<'a> {
    action: &'a CalibrateAction,
    goal: GoalHandle,
    round: Cell<u32>,
    iteration: Cell<u32>,
    feedbacks: Cell<u32>,
    /// The phase of the last feedback sent (0: none yet).
    phase: Cell<u8>,
    cancel_seen: Cell<Option<Instant>>,
}

impl<'a> Running<'a> {
    fn new(action: &'a CalibrateAction, goal: GoalHandle) -> Self {
        Self {
            action,
            goal,
            round: Cell::new(1),
            iteration: Cell::new(0),
            feedbacks: Cell::new(0),
            phase: Cell::new(0),
            cancel_seen: Cell::new(None),
        }
    }

    /// Where the goal's work stands, in words (by its last feedback).
    pub fn stage(&self) -> &'static str {
        match self.phase.get() {
            CalibrateFeedback::PHASE_DIAGNOSIS => "the diagnosis",
            0 => "the start",
            _ => "the calibration",
        }
    }

    /// The core's progress observer: feedback of each iteration and round, and
    /// `Flow::Stop` once a client asked to cancel the goal.
    pub fn observe(&self, p: &Progress) -> Flow {
        let feedback = match *p {
            Progress::Iteration { step, cost, .. } => {
                self.iteration.set(self.iteration.get() + 1);
                CalibrateFeedback {
                    phase: CalibrateFeedback::PHASE_ITERATION,
                    round: self.round.get(),
                    step: if step == Step::Direct { 1 } else { 2 },
                    iteration: self.iteration.get(),
                    cost,
                    ..CalibrateFeedback::default()
                }
            }
            Progress::NoiseRound { round, estimate } => {
                let (noise_groups, _, noise_estimated) = noise_si(estimate);
                let round = u32::try_from(round).unwrap_or(u32::MAX);
                self.round.set(round.saturating_add(1));
                self.iteration.set(0);
                CalibrateFeedback {
                    phase: CalibrateFeedback::PHASE_NOISE_ROUND,
                    round,
                    iteration: 0,
                    noise_groups,
                    noise_estimated,
                    ..CalibrateFeedback::default()
                }
            }
        };
        self.send(feedback);
        if self.cancelled() {
            Flow::Stop
        } else {
            Flow::Continue
        }
    }

    /// The calibration is done and the diagnosis begins (a cancel that comes meanwhile
    /// stops it: [`Running::cancelled`] is asked while it runs).
    pub fn diagnosing(&self) {
        self.send(CalibrateFeedback {
            phase: CalibrateFeedback::PHASE_DIAGNOSIS,
            round: self.round.get().saturating_sub(1).max(1),
            ..CalibrateFeedback::default()
        });
    }

    fn send(&self, feedback: CalibrateFeedback) {
        self.feedbacks.set(self.feedbacks.get() + 1);
        self.phase.set(feedback.phase);
        self.action.server.feedback(self.goal, feedback);
    }

    /// Whether a client asked to cancel the goal (the first time it is seen is kept).
    pub fn cancelled(&self) -> bool {
        if self.cancel_seen.get().is_none() && self.action.server.canceling(self.goal) {
            self.cancel_seen.set(Some(Instant::now()));
        }
        self.cancel_seen.get().is_some()
    }

    /// Ends the goal: succeeded with `result`, aborted (its message says why), or canceled.
    pub fn finish(self, ctx: &NodeContext, end: GoalEnd, mut result: CalibrateResult) {
        let after = self.cancel_seen.get().map(|t| {
            format!(
                " ({:.1} ms after the cancel request was seen)",
                ms_from_seconds(t.elapsed().as_secs_f64())
            )
        });
        if end == GoalEnd::Canceled {
            let why = std::mem::take(&mut result.message);
            result.message = format!(
                "cancelled{}{}{why}",
                after.clone().unwrap_or_default(),
                if why.is_empty() { "" } else { ": " }
            );
        }
        ctx.log(format!(
            "{}{}: goal {} {}: {} feedback messages; {}",
            if end == GoalEnd::Aborted {
                "WARN: "
            } else {
                ""
            },
            self.action.server.name(),
            self.goal,
            match end {
                GoalEnd::Succeeded => "succeeded",
                GoalEnd::Aborted => "aborted",
                GoalEnd::Canceled => "canceled",
            },
            self.feedbacks.get(),
            result.message
        ));
        self.action.server.finish(self.goal, end, result);
    }
}

/// The noise groups of `estimate` and their stated and estimated levels in SI (the core
/// reports µm and µrad).
pub fn noise_si(estimate: &NoiseEstimate) -> (Vec<String>, Vec<f64>, Vec<f64>) {
    let groups = &estimate.groups;
    (
        groups.iter().map(|g| g.group.to_owned()).collect(),
        groups.iter().map(|g| m_from_um(g.assumed)).collect(),
        groups.iter().map(|g| m_from_um(g.estimated)).collect(),
    )
}
