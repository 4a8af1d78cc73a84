//! Actions a node serves from its own loop (the calibrator's `~/calibrate`): the services
//! `~/<action>/_action/send_goal`, `cancel_goal`, `get_result` (each answering either ROS 2
//! request mapping, [`crate::dds_rpc`], so that an action client on rmw_fastrtps or
//! rmw_cyclonedds gets its replies) and the topics `feedback`, `status`, named and typed as
//! rclcpp's, with the goals' states kept here and polled by the node: no task, nothing waits. The node takes a goal as it comes ([`ActionServer::next_goal`]:
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

use ros2_client::action::{GoalId, GoalInfo, GoalStatusEnum, SendGoalResponse};
use ros2_client::action_msgs::{
    CancelGoalResponse, CancelGoalResponseEnum, GoalStatus, GoalStatusArray,
};
use ros2_client::builtin_interfaces::Time;
use ros2_client::dds::rustdds::TopicKind;
use ros2_client::{Publisher, QosProfile};
use serde::{Deserialize, Serialize};

use rpkm_msgs::RosMessage;

use crate::dds::DdsNode;
use crate::dds_rpc::{Caller, RpcServer, RpcTypes};
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
    request: Caller,
}

/// `<action>_SendGoal_Request`: the goal's id and the goal.
#[derive(Serialize, Deserialize)]
struct GoalRequest<G> {
    goal_id: GoalId,
    goal: G,
}

/// `<action>_GetResult_Request`.
#[derive(Serialize, Deserialize)]
struct ResultRequest {
    goal_id: GoalId,
}

/// `<action>_GetResult_Response`.
#[derive(Serialize, Deserialize)]
struct ResultReply<R> {
    status: GoalStatusEnum,
    result: R,
}

/// `action_msgs/CancelGoal_Request`: a goal id, or every goal accepted at or before a stamp.
#[derive(Serialize, Deserialize)]
struct CancelRequest {
    goal_info: GoalInfo,
}

/// `<action>_FeedbackMessage`.
#[derive(Debug, Serialize, Deserialize)]
struct FeedbackMessage<F> {
    goal_id: GoalId,
    feedback: F,
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
    waiting: Vec<(GoalId, Caller)>,
}

/// One action of a node: `~/<action>` of type `<package>/action/<type>`.
pub struct ActionServer<G: RosMessage, R: RosMessage + Default, F: RosMessage> {
    goal: RpcServer<GoalRequest<G>, SendGoalResponse>,
    cancel: RpcServer<CancelRequest, CancelGoalResponse>,
    result: RpcServer<ResultRequest, ResultReply<R>>,
    feedback: Publisher<FeedbackMessage<F>>,
    status: Publisher<GoalStatusArray>,
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
        let (package, type_name) = (kind.package, kind.name);
        let service = |name: &str| format!("{action}/_action/{name}");
        let goal = self
            .rpc_server(
                &service("send_goal"),
                &RpcTypes::new(package, "action", &format!("{type_name}_SendGoal")),
            )
            .map_err(err)?;
        let cancel = self
            .rpc_server(
                &service("cancel_goal"),
                &RpcTypes::new("action_msgs", "srv", "CancelGoal"),
            )
            .map_err(err)?;
        let result = self
            .rpc_server(
                &service("get_result"),
                &RpcTypes::new(package, "action", &format!("{type_name}_GetResult")),
            )
            .map_err(err)?;
        let keep = |depth| {
            QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth })
        };
        // rcl_action's: feedback reliable, volatile; the status transient-local, last 1 (a
        // late client reads the goals' states)
        let feedback = self
            .action_publisher(
                &service("feedback"),
                &format!("{package}::action::dds_::{type_name}_FeedbackMessage_"),
                keep(FEEDBACK_DEPTH),
            )
            .map_err(err)?;
        let status = self
            .action_publisher(
                &service("status"),
                "action_msgs::msg::dds_::GoalStatusArray_",
                keep(1).durability(ros2_client::qos::Durability::TransientLocal),
            )
            .map_err(err)?;
        let name = goal
            .name()
            .trim_end_matches("/_action/send_goal")
            .to_owned();
        Ok(ActionServer {
            goal,
            cancel,
            result,
            feedback,
            status,
            goals: RefCell::new(Goals {
                all: BTreeMap::new(),
                finished: VecDeque::new(),
                waiting: Vec::new(),
            }),
            name,
        })
    }

    /// A writer of this node's topic `~/<topic>` of DDS type `dds_type` (an action's
    /// feedback or status, whose types are not messages of a package's `msg`).
    fn action_publisher<M: Serialize>(
        &self,
        topic: &str,
        dds_type: &str,
        qos: QosProfile,
    ) -> Result<Publisher<M>, String> {
        let mut node = self
            .node
            .lock()
            .map_err(|_| "the DDS node mutex is poisoned".to_owned())?;
        let name = format!("rt{}/{topic}", node.fully_qualified_name());
        let dds_qos = ros2_client::dds::rustdds::QosPolicies::from(&qos);
        let topic = self
            .participant()
            .create_topic(
                name.clone(),
                dds_type.to_owned(),
                &dds_qos,
                TopicKind::NoKey,
            )
            .map_err(|e| format!("{name}: {e}"))?;
        node.create_publisher(&topic, Some(qos))
            .map_err(|e| format!("{name}: {e}"))
    }
}

impl<G: RosMessage, R: RosMessage + Default, F: RosMessage> ActionServer<G, R, F> {
    /// The action's name (`/rpkm/calibrator/calibrate`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Answers the cancel and result requests waiting, and sends the replies whose readers
    /// have matched since.
    pub fn poll(&self) {
        self.serve_cancels();
        self.serve_results();
        self.goal.flush();
        self.cancel.flush();
        self.result.flush();
    }

    /// The next goal a client sent and what it asks, if any; the node accepts or rejects it
    /// at once. A goal id the server already knows is refused (a client resending its
    /// request).
    pub fn next_goal(&self) -> Option<(NewGoal, G)> {
        loop {
            let (request, sent) = self.goal.try_next()?;
            let goal = NewGoal {
                id: sent.goal_id,
                request,
            };
            if !self.goals.borrow().all.contains_key(&goal.id) {
                return Some((goal, sent.goal));
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
        let message = FeedbackMessage {
            goal_id: h.0,
            feedback,
        };
        if let Err(e) = self.feedback.publish(message) {
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

    fn reply_goal(&self, request: Caller, accepted: bool, stamp: Time) {
        self.goal
            .reply(request, &SendGoalResponse { accepted, stamp });
    }

    fn send_result(&self, request: Caller, status: GoalStatusEnum, result: R) {
        self.result.reply(request, &ResultReply { status, result });
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
        if let Err(e) = self.status.publish(GoalStatusArray { status_list }) {
            log::warn!("action {}: status not published: {e}", self.name);
        }
    }

    /// Answers the result requests waiting: a finished goal's result now, a running goal's
    /// when it ends, an unknown goal's as rclcpp does (status unknown, an empty result).
    fn serve_results(&self) {
        while let Some((request, asked)) = self.result.try_next() {
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
        while let Some((request, cancel)) = self.cancel.try_next() {
            let response = self.cancel_goals(&cancel.goal_info);
            if !response.goals_canceling.is_empty() {
                self.publish_status();
            }
            self.cancel.reply(request, &response);
        }
    }

    /// The goals `target` names start canceling (rcl_action's rules); the reply.
    fn cancel_goals(&self, target: &GoalInfo) -> CancelGoalResponse {
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
