//! Managed (lifecycle) nodes, as rclcpp_lifecycle has them: the states unconfigured,
//! inactive, active and finalized; the transitions configure, cleanup, activate, deactivate
//! and shutdown, each through its transition state (configuring, ...); the services
//! `~/change_state`, `~/get_state`, `~/get_available_states`, `~/get_available_transitions`
//! and the topic `~/transition_event` (`lifecycle_msgs`, on DDS), so that `ros2 lifecycle
//! set /rpkm/tcp_estimator configure` and rclcpp's clients drive rpkm's nodes.
//!
//! ros2-client has no lifecycle support: this is the state machine of rcl_lifecycle's
//! default one, on the node's own services ([`rpkm_transport::dds_calls`]). The node performs
//! each transition between samples ([`Lifecycle::next`], then [`Lifecycle::finish`] with its
//! outcome): configure re-reads its parameters, and only an active node publishes.

use rpkm_msgs::lifecycle_msgs::{
    ChangeStateRequest, ChangeStateResponse, EmptyRequest, GetAvailableStatesResponse,
    GetAvailableTransitionsResponse, GetStateResponse, State, Transition, TransitionDescription,
    TransitionEvent,
};
use rpkm_transport::dds_calls::{Call, CallServer, ServiceType};
use rpkm_transport::{Backend, Publisher, Qos, Topic};

use super::context::NodeContext;

/// The state a node starts in: unconfigured with `--unconfigured`, else active.
pub fn start(args: &super::context::CommonArgs) -> Primary {
    if args.unconfigured {
        Primary::Unconfigured
    } else {
        Primary::Active
    }
}

/// A primary state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Primary {
    Unconfigured,
    Inactive,
    Active,
    Finalized,
}

impl Primary {
    /// Its `lifecycle_msgs/State`.
    pub fn state(self) -> State {
        match self {
            Self::Unconfigured => State::new(State::PRIMARY_STATE_UNCONFIGURED, "unconfigured"),
            Self::Inactive => State::new(State::PRIMARY_STATE_INACTIVE, "inactive"),
            Self::Active => State::new(State::PRIMARY_STATE_ACTIVE, "active"),
            Self::Finalized => State::new(State::PRIMARY_STATE_FINALIZED, "finalized"),
        }
    }
}

/// What a node does in a transition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TransitionStep {
    /// Re-read its parameters and set itself up from them.
    Configure,
    /// Forget its configuration.
    Cleanup,
    /// Start publishing.
    Activate,
    /// Stop publishing.
    Deactivate,
    /// End: finalized, the node publishes nothing and answers its lifecycle services until
    /// it is stopped (SIGTERM), as an rclcpp node stays until it is destroyed.
    Shutdown,
}

/// One transition of the state machine: its id and label, from, through and to which state,
/// and the id of its end (`on_..._success`; the failure is the next id).
struct Edge {
    id: u8,
    label: &'static str,
    step: TransitionStep,
    from: Primary,
    via: (u8, &'static str),
    to: Primary,
    done: u8,
}

/// rcl_lifecycle's default state machine, the transitions a caller may ask for.
const EDGES: [Edge; 7] = [
    Edge {
        id: Transition::TRANSITION_CONFIGURE,
        label: "configure",
        step: TransitionStep::Configure,
        from: Primary::Unconfigured,
        via: (State::TRANSITION_STATE_CONFIGURING, "configuring"),
        to: Primary::Inactive,
        done: Transition::TRANSITION_ON_CONFIGURE_SUCCESS,
    },
    Edge {
        id: Transition::TRANSITION_CLEANUP,
        label: "cleanup",
        step: TransitionStep::Cleanup,
        from: Primary::Inactive,
        via: (State::TRANSITION_STATE_CLEANINGUP, "cleaningup"),
        to: Primary::Unconfigured,
        done: Transition::TRANSITION_ON_CLEANUP_SUCCESS,
    },
    Edge {
        id: Transition::TRANSITION_ACTIVATE,
        label: "activate",
        step: TransitionStep::Activate,
        from: Primary::Inactive,
        via: (State::TRANSITION_STATE_ACTIVATING, "activating"),
        to: Primary::Active,
        done: Transition::TRANSITION_ON_ACTIVATE_SUCCESS,
    },
    Edge {
        id: Transition::TRANSITION_DEACTIVATE,
        label: "deactivate",
        step: TransitionStep::Deactivate,
        from: Primary::Active,
        via: (State::TRANSITION_STATE_DEACTIVATING, "deactivating"),
        to: Primary::Inactive,
        done: Transition::TRANSITION_ON_DEACTIVATE_SUCCESS,
    },
    Edge {
        id: Transition::TRANSITION_UNCONFIGURED_SHUTDOWN,
        label: "shutdown",
        step: TransitionStep::Shutdown,
        from: Primary::Unconfigured,
        via: (State::TRANSITION_STATE_SHUTTINGDOWN, "shuttingdown"),
        to: Primary::Finalized,
        done: Transition::TRANSITION_ON_SHUTDOWN_SUCCESS,
    },
    Edge {
        id: Transition::TRANSITION_INACTIVE_SHUTDOWN,
        label: "shutdown",
        step: TransitionStep::Shutdown,
        from: Primary::Inactive,
        via: (State::TRANSITION_STATE_SHUTTINGDOWN, "shuttingdown"),
        to: Primary::Finalized,
        done: Transition::TRANSITION_ON_SHUTDOWN_SUCCESS,
    },
    Edge {
        id: Transition::TRANSITION_ACTIVE_SHUTDOWN,
        label: "shutdown",
        step: TransitionStep::Shutdown,
        from: Primary::Active,
        via: (State::TRANSITION_STATE_SHUTTINGDOWN, "shuttingdown"),
        to: Primary::Finalized,
        done: Transition::TRANSITION_ON_SHUTDOWN_SUCCESS,
    },
];

/// The edge `request` asks for from `state`: by id, or by label when the id is 0 and a label
/// is given (as rclcpp reads a ChangeState request).
fn edge_for(state: Primary, request: &Transition) -> Option<&'static Edge> {
    EDGES.iter().find(|e| {
        e.from == state
            && if request.id == 0 && !request.label.is_empty() {
                e.label == request.label
            } else {
                e.id == request.id
            }
    })
}

/// Every state of the machine, as `~/get_available_states` lists them.
fn all_states() -> Vec<State> {
    let mut states = vec![State::new(State::PRIMARY_STATE_UNKNOWN, "unknown")];
    states.extend(
        [
            Primary::Unconfigured,
            Primary::Inactive,
            Primary::Active,
            Primary::Finalized,
        ]
        .map(Primary::state),
    );
    for (id, label) in [
        (State::TRANSITION_STATE_CONFIGURING, "configuring"),
        (State::TRANSITION_STATE_CLEANINGUP, "cleaningup"),
        (State::TRANSITION_STATE_SHUTTINGDOWN, "shuttingdown"),
        (State::TRANSITION_STATE_ACTIVATING, "activating"),
        (State::TRANSITION_STATE_DEACTIVATING, "deactivating"),
        (State::TRANSITION_STATE_ERRORPROCESSING, "errorprocessing"),
    ] {
        states.push(State::new(id, label));
    }
    states
}

/// The transitions a caller may ask for in `state`.
fn available(state: Primary) -> Vec<TransitionDescription> {
    EDGES
        .iter()
        .filter(|e| e.from == state)
        .map(|e| TransitionDescription {
            transition: Transition::new(e.id, e.label),
            start_state: e.from.state(),
            goal_state: e.to.state(),
        })
        .collect()
}

/// The lifecycle services of one node.
struct Services {
    change: CallServer<ChangeStateRequest, ChangeStateResponse>,
    get: CallServer<EmptyRequest, GetStateResponse>,
    states: CallServer<EmptyRequest, GetAvailableStatesResponse>,
    transitions: CallServer<EmptyRequest, GetAvailableTransitionsResponse>,
}

/// A transition a caller asked for, which the node performs before [`Lifecycle::finish`].
pub struct Requested {
    edge: &'static Edge,
    call: Call<ChangeStateRequest, ChangeStateResponse>,
}

impl Requested {
    /// What the node does.
    pub fn step(&self) -> TransitionStep {
        self.edge.step
    }
}

/// A node's lifecycle: its state, services and transition events.
pub struct Lifecycle {
    state: Primary,
    services: Option<Services>,
    events: Option<Publisher<TransitionEvent>>,
}

impl Lifecycle {
    /// The lifecycle of `ctx`'s node, starting in `start`. The services and events are on
    /// DDS; without DDS the node stays in `start` (a node started unconfigured needs DDS).
    pub fn open(ctx: &NodeContext, start: Primary) -> anyhow::Result<Self> {
        let Some(dds) = ctx.transport.dds_node() else {
            anyhow::ensure!(
                start == Primary::Active,
                "node {}: a managed node is driven over DDS (--backend dds or both)",
                ctx.name
            );
            return Ok(Self {
                state: start,
                services: None,
                events: None,
            });
        };
        let kind = |name| ServiceType {
            package: "lifecycle_msgs",
            name,
        };
        let services = Services {
            change: dds.serve_calls("change_state", kind("ChangeState"))?,
            get: dds.serve_calls("get_state", kind("GetState"))?,
            states: dds.serve_calls("get_available_states", kind("GetAvailableStates"))?,
            transitions: dds
                .serve_calls("get_available_transitions", kind("GetAvailableTransitions"))?,
        };
        // `~/transition_event`, in the node's namespace like its other topics
        let name = rpkm_transport::names::intern(format!(
            "{}/{}/transition_event",
            rpkm_transport::NODE_NAMESPACE,
            ctx.name
        ));
        let topic: Topic<TransitionEvent> = Topic::new(name, Qos::reliable(10));
        let events = ctx.transport.publisher_on(&topic, Backend::Dds)?;
        Ok(Self {
            state: start,
            services: Some(services),
            events: Some(events),
        })
    }

    /// The state now.
    pub fn state(&self) -> Primary {
        self.state
    }

    /// Whether the node publishes (active).
    pub fn active(&self) -> bool {
        self.state == Primary::Active
    }

    /// Answers the queries waiting (`~/get_state`, `~/get_available_states`,
    /// `~/get_available_transitions`), and nothing else: what the node can do while it is
    /// busy (a calibration goal), a transition waiting for the loop.
    pub fn answer_queries(&self) {
        let Some(s) = self.services.as_ref() else {
            return;
        };
        while let Some(call) = s.get.try_next() {
            call.answer(GetStateResponse {
                current_state: self.state.state(),
            });
        }
        while let Some(call) = s.states.try_next() {
            call.answer(GetAvailableStatesResponse {
                available_states: all_states(),
            });
        }
        while let Some(call) = s.transitions.try_next() {
            call.answer(GetAvailableTransitionsResponse {
                available_transitions: available(self.state),
            });
        }
    }

    /// Answers the queries waiting, and returns the next transition asked for that the state
    /// offers (one it does not offer is refused: `success: false`).
    pub fn next(&mut self, ctx: &NodeContext) -> Option<Requested> {
        self.answer_queries();
        let s = self.services.as_ref()?;
        while let Some(call) = s.change.try_next() {
            let Some(edge) = edge_for(self.state, &call.request.transition) else {
                ctx.log(format!(
                    "WARN: lifecycle: transition {} {:?} is not available in state {}",
                    call.request.transition.id,
                    call.request.transition.label,
                    self.state.state().label
                ));
                call.answer(ChangeStateResponse { success: false });
                continue;
            };
            self.event(
                Transition::new(edge.id, edge.label),
                self.state.state(),
                State::new(edge.via.0, edge.via.1),
            );
            return Some(Requested { edge, call });
        }
        None
    }

    /// Ends the transition `r` with the node's `outcome`: on success the goal state, on a
    /// failure back where it started (the reason logged); the caller gets its reply and
    /// `~/transition_event` says it.
    pub fn finish(&mut self, r: Requested, outcome: Result<(), String>, ctx: &NodeContext) {
        let via = State::new(r.edge.via.0, r.edge.via.1);
        let (end, success) = match outcome {
            Ok(()) => (Transition::new(r.edge.done, "transition_success"), true),
            Err(why) => {
                ctx.log(format!("WARN: lifecycle: {} failed: {why}", r.edge.label));
                (
                    Transition::new(r.edge.done + 1, "transition_failure"),
                    false,
                )
            }
        };
        self.state = if success { r.edge.to } else { r.edge.from };
        self.event(end, via, self.state.state());
        ctx.log(format!(
            "lifecycle: {} -> {}",
            r.edge.label,
            self.state.state().label
        ));
        r.call.answer(ChangeStateResponse { success });
    }

    /// Performs the transition asked for, if any: `configure` sets the node up from its
    /// parameters read again (the other transitions change only what it publishes).
    pub fn serve(&mut self, ctx: &NodeContext, configure: impl FnOnce() -> Result<(), String>) {
        if let Some(r) = self.next(ctx) {
            let outcome = if r.step() == TransitionStep::Configure {
                configure()
            } else {
                Ok(())
            };
            self.finish(r, outcome, ctx);
        }
    }

    fn event(&self, transition: Transition, start_state: State, goal_state: State) {
        let Some(events) = &self.events else { return };
        let timestamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        let msg = TransitionEvent {
            timestamp,
            transition,
            start_state,
            goal_state,
        };
        if let Err(e) = events.publish(&msg) {
            log::warn!("transition event not published: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_state_machine_is_rcl_lifecycle_s() {
        let by_id = |s, id| edge_for(s, &Transition::new(id, "")).map(|e| (e.to, e.done));
        assert_eq!(
            by_id(Primary::Unconfigured, 1),
            Some((Primary::Inactive, 10))
        );
        assert_eq!(by_id(Primary::Inactive, 3), Some((Primary::Active, 30)));
        assert_eq!(by_id(Primary::Active, 4), Some((Primary::Inactive, 40)));
        assert_eq!(
            by_id(Primary::Inactive, 2),
            Some((Primary::Unconfigured, 20))
        );
        assert_eq!(by_id(Primary::Active, 7), Some((Primary::Finalized, 50)));
        // not offered: activate an unconfigured node, configure an active one, shut down
        // an active node by the inactive node's id
        assert_eq!(by_id(Primary::Unconfigured, 3), None);
        assert_eq!(by_id(Primary::Active, 1), None);
        assert_eq!(by_id(Primary::Active, 6), None);
        // by label when the id is 0
        let by_label = |s, l: &str| edge_for(s, &Transition::new(0, l)).map(|e| e.id);
        assert_eq!(by_label(Primary::Inactive, "shutdown"), Some(6));
        assert_eq!(by_label(Primary::Unconfigured, "configure"), Some(1));
        let offered: Vec<u8> = available(Primary::Inactive)
            .iter()
            .map(|d| d.transition.id)
            .collect();
        assert_eq!(offered, [2, 3, 6]);
        assert_eq!(all_states().len(), 11);
    }
}
