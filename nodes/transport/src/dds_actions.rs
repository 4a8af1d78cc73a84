//! Actions a node serves from its own loop (the calibrator's `~/calibrate`): ros2-client's
//! action server (the services `~/<action>/_action/send_goal`, `cancel_goal`, `get_result`
//! and the topics `feedback`, `status`, named and typed as rclcpp's, on the Cyclone service
//! mapping as [`crate::dds_calls`]), with the goals' states kept here and polled by the node:
//! no task, nothing waits. The node takes a goal as it comes ([`ActionServer::next_goal`]:
//! accept or reject), publishes feedback while it works and asks whether the goal is being
//! cancelled ([`ActionServer::canceling`]), and ends it with its result
//! ([`ActionServer::finish`]); the result goes to every client that asked for it, also to
//! one that asks later. Between goals [`ActionServer::poll`] answers cancel and result
//! requests.
//!
//! Cancel requests follow rcl_action's rules: a goal id, or every goal accepted at or before
//! a stamp, or (both zero) every goal; only an accepted or executing goal starts canceling.

use std::cell::RefCell;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use ros2_client::action::{
    self, ActionServerQosPolicies, GetResultResponse, GoalId, GoalInfo, GoalStatusEnum,
    SendGoalResponse,
};
use ros2_client::action_msgs::{
    CancelGoalResponse, CancelGoalResponseEnum, GoalStatus, GoalStatusArray,
};
use ros2_client::builtin_interfaces::Time;
use ros2_client::{ActionTypeName, Name, QosProfile, RmwRequestId, ServiceMapping};

use rpkm_msgs::RosMessage;

use crate::dds::{DdsNode, Wire};
use crate::error::TransportError;

/// Finished goals whose results are kept for a late `get_result`.
const FINISHED_KEPT: usize = 16;
/// Feedback messages the writer keeps for a reader that lags: one per LM iteration of a
/// calibration is a few hundred; with rclcpp's 10 a slow reader would lose some.
const FEEDBACK_DEPTH: usize = 1000;

/// What an action's type is named by: `rpkm_msgs`, `Calibrate` for
/// `rpkm_msgs/action/Calibrate`.
#[derive(Debug, Clone, Copy)]
pub struct ActionType {
    pub package: &'static str,
    pub name: &'static str,
}

/// A goal as it came, to accept or reject (once: its request gets one reply).
#[derive(Clone, Copy)]
pub struct NewGoal {
    id: GoalId,
    request: RmwRequestId,
}

/// An accepted goal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GoalHandle(GoalId);

impl std::fmt::Display for GoalHandle {
    /// The goal id as 32 hex digits.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.0)
    }
}

/// How a goal ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GoalEnd {
    Succeeded,
    /// The node could not reach the goal (its result says why).
    Aborted,
    /// Ended on a client's cancel request.
    Canceled,
}

/// One goal's state, and its result once it ended.
struct Goal<R> {
    status: GoalStatusEnum,
    accepted: Time,
    result: Option<R>,
}

/// Every goal the server knows, the finished ones in the order they ended, and the result
/// requests of goals still running.
struct Goals<R> {
    all: BTreeMap<GoalId, Goal<R>>,
    finished: VecDeque<GoalId>,
    waiting: Vec<(GoalId, RmwRequestId)>,
}

/// One action of a node: `~/<action>` of type `<package>/action/<type>`.
pub struct ActionServer<G: RosMessage, R: RosMessage + Default, F: RosMessage> {
    server: action::ActionServer<Wire<G>, Wire<R>, Wire<F>>,
    goals: RefCell<Goals<R>>,
    name: String,
}

impl<G: RosMessage, R: RosMessage + Default, F: RosMessage> std::fmt::Debug
    for ActionServer<G, R, F>
{
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ActionServer")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

impl DdsNode {
    /// Serves `~/<action>` (relative to this node: `/rpkm/calibrator/<action>`) of type
    /// `kind`.
    pub fn serve_action<G, R, F>(
        self: &Arc<Self>,
        action: &str,
        kind: ActionType,
    ) -> Result<ActionServer<G, R, F>, TransportError>
    where
        G: RosMessage,
        R: RosMessage + Default,
        F: RosMessage,
    {
        let err = |reason: String| TransportError::CreatePort {
            topic: format!("~/{action}"),
            backend: "dds",
            port: "action server",
            reason,
        };
        let mut node = self
            .node
            .lock()
            .map_err(|_| err("node mutex poisoned".into()))?;
        let fqn = node.fully_qualified_name();
        let name = Name::new(&fqn, action).map_err(|e| err(format!("{e:?}")))?;
        let keep = |depth| {
            QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth })
        };
        // rcl_action's: services reliable, volatile, last 10; the status transient-local,
        // last 1 (a late client reads the goals' states)
        let qos = ActionServerQosPolicies {
            goal_service: keep(10),
            result_service: keep(10),
            cancel_service: keep(10),
            feedback_publisher: keep(FEEDBACK_DEPTH),
            status_publisher: keep(1).durability(ros2_client::qos::Durability::TransientLocal),
        };
        let server = node
            .create_action_server::<Wire<G>, Wire<R>, Wire<F>>(
                ServiceMapping::Cyclone,
                &name,
                &ActionTypeName::new(kind.package, kind.name),
                qos,
            )
            .map_err(|e| err(e.to_string()))?;
        Ok(ActionServer {
            server,
            goals: RefCell::new(Goals {
                all: BTreeMap::new(),
                finished: VecDeque::new(),
                waiting: Vec::new(),
            }),
            name: format!("{fqn}/{action}"),
        })
    }
}

impl<G: RosMessage, R: RosMessage + Default, F: RosMessage> ActionServer<G, R, F> {
    /// The action's name (`/rpkm/calibrator/calibrate`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Answers the cancel and result requests waiting.
    pub fn poll(&self) {
        self.serve_cancels();
        self.serve_results();
    }

    /// The next goal a client sent and what it asks, if any; the node accepts or rejects it
    /// at once. A goal id the server already knows is refused (a client resending its
    /// request).
    pub fn next_goal(&self) -> Option<(NewGoal, G)> {
        loop {
            let (request, sent) = match self.server.receive_goal() {
                Ok(Some(got)) => got,
                Ok(None) => return None,
                Err(e) => {
                    log::warn!("action {}: bad goal request: {e:?}", self.name);
                    return None;
                }
            };
            let goal = NewGoal {
                id: sent.goal_id,
                request,
            };
            if !self.goals.borrow().all.contains_key(&goal.id) {
                return Some((goal, sent.goal.0));
            }
            self.reject(goal);
        }
    }

    /// Accepts `goal`: it executes from now on (the status says accepted, then executing).
    pub fn accept(&self, goal: NewGoal) -> GoalHandle {
        let NewGoal { id, request } = goal;
        let accepted = Time::now();
        self.goals.borrow_mut().all.insert(
            id,
            Goal {
                status: GoalStatusEnum::Accepted,
                accepted,
                result: None,
            },
        );
        self.reply_goal(request, true, accepted);
        self.publish_status();
        self.set_status(id, GoalStatusEnum::Executing);
        GoalHandle(id)
    }

    /// Refuses `goal` (a client sees `accepted: false`).
    pub fn reject(&self, goal: NewGoal) {
        self.reply_goal(goal.request, false, Time::now());
    }

    /// Publishes `feedback` of the goal `h`.
    pub fn feedback(&self, h: GoalHandle, feedback: F) {
        if let Err(e) = self.server.send_feedback(h.0, Wire(feedback)) {
            log::warn!("action {}: feedback not sent: {e}", self.name);
        }
    }

    /// Whether a client asked to cancel the goal `h` (the cancel requests waiting are
    /// answered first).
    pub fn canceling(&self, h: GoalHandle) -> bool {
        self.serve_cancels();
        self.goals
            .borrow()
            .all
            .get(&h.0)
            .is_some_and(|g| g.status == GoalStatusEnum::Canceling)
    }

    /// Ends the goal `h` with `result`: the clients that asked for it get it now, later ones
    /// when they ask (the last [`FINISHED_KEPT`] goals' results are kept).
    pub fn finish(&self, h: GoalHandle, end: GoalEnd, result: R) {
        let status = match end {
            GoalEnd::Succeeded => GoalStatusEnum::Succeeded,
            GoalEnd::Aborted => GoalStatusEnum::Aborted,
            GoalEnd::Canceled => GoalStatusEnum::Canceled,
        };
        let waiting = {
            let mut goals = self.goals.borrow_mut();
            if let Some(g) = goals.all.get_mut(&h.0) {
                g.status = status;
            }
            let (mine, others): (Vec<_>, Vec<_>) =
                goals.waiting.drain(..).partition(|(id, _)| *id == h.0);
            goals.waiting = others;
            mine
        };
        for (_, request) in waiting {
            self.send_result(request, status, result.clone());
        }
        {
            let mut goals = self.goals.borrow_mut();
            if let Some(g) = goals.all.get_mut(&h.0) {
                g.result = Some(result);
            }
            goals.finished.push_back(h.0);
            while goals.finished.len() > FINISHED_KEPT {
                if let Some(old) = goals.finished.pop_front() {
                    goals.all.remove(&old);
                }
            }
        }
        self.publish_status();
        self.serve_results();
    }

    fn reply_goal(&self, request: RmwRequestId, accepted: bool, stamp: Time) {
        if let Err(e) = self
            .server
            .send_goal_response(request, SendGoalResponse { accepted, stamp })
        {
            log::warn!("action {}: goal reply not sent: {e:?}", self.name);
        }
    }

    fn send_result(&self, request: RmwRequestId, status: GoalStatusEnum, result: R) {
        let reply = GetResultResponse {
            status,
            result: Wire(result),
        };
        if let Err(e) = self.server.send_result(request, reply) {
            log::warn!("action {}: result not sent: {e:?}", self.name);
        }
    }

    fn set_status(&self, id: GoalId, status: GoalStatusEnum) {
        if let Some(g) = self.goals.borrow_mut().all.get_mut(&id) {
            g.status = status;
        }
        self.publish_status();
    }

    /// Every known goal's state on `_action/status`.
    fn publish_status(&self) {
        let status_list = self
            .goals
            .borrow()
            .all
            .iter()
            .map(|(id, g)| GoalStatus {
                goal_info: GoalInfo {
                    goal_id: *id,
                    stamp: g.accepted,
                },
                status: g.status,
            })
            .collect();
        if let Err(e) = self
            .server
            .send_goal_statuses(GoalStatusArray { status_list })
        {
            log::warn!("action {}: status not published: {e:?}", self.name);
        }
    }

    /// Answers the result requests waiting: a finished goal's result now, a running goal's
    /// when it ends, an unknown goal's as rclcpp does (status unknown, an empty result).
    fn serve_results(&self) {
        loop {
            let (request, asked) = match self.server.receive_result_request() {
                Ok(Some(got)) => got,
                Ok(None) => return,
                Err(e) => {
                    log::warn!("action {}: bad result request: {e:?}", self.name);
                    return;
                }
            };
            let known = self
                .goals
                .borrow()
                .all
                .get(&asked.goal_id)
                .map(|g| (g.status, g.result.clone()));
            match known {
                Some((status, Some(result))) => self.send_result(request, status, result),
                Some((_, None)) => self
                    .goals
                    .borrow_mut()
                    .waiting
                    .push((asked.goal_id, request)),
                None => self.send_result(request, GoalStatusEnum::Unknown, R::default()),
            }
        }
    }

    /// Answers the cancel requests waiting; the goals they name start canceling.
    fn serve_cancels(&self) {
        loop {
            let (request, cancel) = match self.server.receive_cancel_request() {
                Ok(Some(got)) => got,
                Ok(None) => return,
                Err(e) => {
                    log::warn!("action {}: bad cancel request: {e:?}", self.name);
                    return;
                }
            };
            let response = match cancel_target(&cancel) {
                Some(target) => self.cancel(&target),
                None => CancelGoalResponse {
                    return_code: CancelGoalResponseEnum::Rejected,
                    goals_canceling: Vec::new(),
                },
            };
            if !response.goals_canceling.is_empty() {
                self.publish_status();
            }
            if let Err(e) = self.server.send_cancel_response(request, response) {
                log::warn!("action {}: cancel reply not sent: {e:?}", self.name);
            }
        }
    }

    /// The goals `target` names start canceling (rcl_action's rules); the reply.
    fn cancel(&self, target: &GoalInfo) -> CancelGoalResponse {
        let by_id = target.goal_id != GoalId::ZERO;
        let by_time = target.stamp != Time::ZERO;
        let mut goals = self.goals.borrow_mut();
        let mut goals_canceling = Vec::new();
        let mut terminated = false;
        for (id, g) in &mut goals.all {
            let named = (by_id && *id == target.goal_id)
                || (by_time && g.accepted <= target.stamp)
                || (!by_id && !by_time);
            if !named {
                continue;
            }
            match g.status {
                GoalStatusEnum::Accepted | GoalStatusEnum::Executing => {
                    g.status = GoalStatusEnum::Canceling;
                    goals_canceling.push(GoalInfo {
                        goal_id: *id,
                        stamp: g.accepted,
                    });
                }
                GoalStatusEnum::Canceling | GoalStatusEnum::Unknown => {}
                _ => terminated = true,
            }
        }
        let return_code = if !goals_canceling.is_empty() {
            CancelGoalResponseEnum::None
        } else if by_id && !goals.all.contains_key(&target.goal_id) {
            CancelGoalResponseEnum::UnknownGoal
        } else if terminated {
            CancelGoalResponseEnum::GoalTerminated
        } else {
            CancelGoalResponseEnum::Rejected
        };
        CancelGoalResponse {
            return_code,
            goals_canceling,
        }
    }
}

/// The goal a cancel request names: ros2-client keeps the request's field crate-private, its
/// serde form is public, so it is read back through CDR.
fn cancel_target(request: &action::CancelGoalRequest) -> Option<GoalInfo> {
    #[derive(serde::Deserialize)]
    struct Target {
        goal_info: GoalInfo,
    }
    let bytes = cdr_encoding::to_vec::<_, byteorder::LittleEndian>(request).ok()?;
    cdr_encoding::from_bytes::<Target, byteorder::LittleEndian>(&bytes)
        .ok()
        .map(|(t, _)| t.goal_info)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cancel request as a client writes it (goal id, stamp) is read back whole.
    #[test]
    fn a_cancel_request_names_its_goal() {
        #[derive(serde::Serialize)]
        struct Written {
            goal_info: GoalInfo,
        }
        let goal_id = GoalId::new_random();
        let stamp = Time::new(1_700_000_000, 250);
        let bytes = cdr_encoding::to_vec::<_, byteorder::LittleEndian>(&Written {
            goal_info: GoalInfo { goal_id, stamp },
        })
        .expect("encode");
        let (request, _) =
            cdr_encoding::from_bytes::<action::CancelGoalRequest, byteorder::LittleEndian>(&bytes)
                .expect("decode");
        let target = cancel_target(&request).expect("a target");
        assert_eq!((target.goal_id, target.stamp), (goal_id, stamp));
    }
}
