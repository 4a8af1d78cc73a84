//! `lifecycle_msgs` (ROS 2's rcl_interfaces): the messages and services of a managed node,
//! field for field, so that `ros2 lifecycle` and rclcpp's clients drive rpkm's nodes.

use serde::{Deserialize, Serialize};

/// `lifecycle_msgs/msg/State`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct State {
    /// `uint8 id`.
    pub id: u8,
    /// `string label`.
    pub label: String,
}

impl State {
    pub const PRIMARY_STATE_UNKNOWN: u8 = 0;
    pub const PRIMARY_STATE_UNCONFIGURED: u8 = 1;
    pub const PRIMARY_STATE_INACTIVE: u8 = 2;
    pub const PRIMARY_STATE_ACTIVE: u8 = 3;
    pub const PRIMARY_STATE_FINALIZED: u8 = 4;
    pub const TRANSITION_STATE_CONFIGURING: u8 = 10;
    pub const TRANSITION_STATE_CLEANINGUP: u8 = 11;
    pub const TRANSITION_STATE_SHUTTINGDOWN: u8 = 12;
    pub const TRANSITION_STATE_ACTIVATING: u8 = 13;
    pub const TRANSITION_STATE_DEACTIVATING: u8 = 14;
    pub const TRANSITION_STATE_ERRORPROCESSING: u8 = 15;

    /// A state by id and label.
    pub fn new(id: u8, label: &str) -> Self {
        Self {
            id,
            label: label.to_owned(),
        }
    }
}

/// `lifecycle_msgs/msg/Transition`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Transition {
    /// `uint8 id`.
    pub id: u8,
    /// `string label`.
    pub label: String,
}

impl Transition {
    pub const TRANSITION_CREATE: u8 = 0;
    pub const TRANSITION_CONFIGURE: u8 = 1;
    pub const TRANSITION_CLEANUP: u8 = 2;
    pub const TRANSITION_ACTIVATE: u8 = 3;
    pub const TRANSITION_DEACTIVATE: u8 = 4;
    pub const TRANSITION_UNCONFIGURED_SHUTDOWN: u8 = 5;
    pub const TRANSITION_INACTIVE_SHUTDOWN: u8 = 6;
    pub const TRANSITION_ACTIVE_SHUTDOWN: u8 = 7;
    pub const TRANSITION_DESTROY: u8 = 8;
    pub const TRANSITION_ON_CONFIGURE_SUCCESS: u8 = 10;
    pub const TRANSITION_ON_CONFIGURE_FAILURE: u8 = 11;
    pub const TRANSITION_ON_CONFIGURE_ERROR: u8 = 12;
    pub const TRANSITION_ON_CLEANUP_SUCCESS: u8 = 20;
    pub const TRANSITION_ON_CLEANUP_FAILURE: u8 = 21;
    pub const TRANSITION_ON_CLEANUP_ERROR: u8 = 22;
    pub const TRANSITION_ON_ACTIVATE_SUCCESS: u8 = 30;
    pub const TRANSITION_ON_ACTIVATE_FAILURE: u8 = 31;
    pub const TRANSITION_ON_ACTIVATE_ERROR: u8 = 32;
    pub const TRANSITION_ON_DEACTIVATE_SUCCESS: u8 = 40;
    pub const TRANSITION_ON_DEACTIVATE_FAILURE: u8 = 41;
    pub const TRANSITION_ON_DEACTIVATE_ERROR: u8 = 42;
    pub const TRANSITION_ON_SHUTDOWN_SUCCESS: u8 = 50;
    pub const TRANSITION_ON_SHUTDOWN_FAILURE: u8 = 51;
    pub const TRANSITION_ON_SHUTDOWN_ERROR: u8 = 52;
    pub const TRANSITION_ON_ERROR_SUCCESS: u8 = 60;
    pub const TRANSITION_ON_ERROR_FAILURE: u8 = 61;
    pub const TRANSITION_ON_ERROR_ERROR: u8 = 62;

    /// A transition by id and label.
    pub fn new(id: u8, label: &str) -> Self {
        Self {
            id,
            label: label.to_owned(),
        }
    }
}

/// `lifecycle_msgs/msg/TransitionDescription`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TransitionDescription {
    pub transition: Transition,
    pub start_state: State,
    pub goal_state: State,
}

/// `lifecycle_msgs/msg/TransitionEvent`, published on `~/transition_event` at every change
/// of state (a transition's start and its end).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct TransitionEvent {
    /// `uint64 timestamp`: ns since the Unix epoch.
    pub timestamp: u64,
    pub transition: Transition,
    pub start_state: State,
    pub goal_state: State,
}

/// `lifecycle_msgs/srv/ChangeState` request.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ChangeStateRequest {
    /// By id, or by label when the id is 0 and a label is given (as rclcpp reads it).
    pub transition: Transition,
}

/// `lifecycle_msgs/srv/ChangeState` response.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ChangeStateResponse {
    pub success: bool,
}

/// The request of `GetState`, `GetAvailableStates`, `GetAvailableTransitions`: no field, so
/// rosidl adds one byte (`structure_needs_at_least_one_member`).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct EmptyRequest {
    pub structure_needs_at_least_one_member: u8,
}

/// `lifecycle_msgs/srv/GetState` response.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct GetStateResponse {
    pub current_state: State,
}

/// `lifecycle_msgs/srv/GetAvailableStates` response.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct GetAvailableStatesResponse {
    pub available_states: Vec<State>,
}

/// `lifecycle_msgs/srv/GetAvailableTransitions` response.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct GetAvailableTransitionsResponse {
    pub available_transitions: Vec<TransitionDescription>,
}

const STATE: &str = "uint8 id\nstring label\n";
const TRANSITION: &str = "uint8 id\nstring label\n";

crate::ros_message!(State, "lifecycle_msgs", "State", STATE, []);
crate::ros_message!(Transition, "lifecycle_msgs", "Transition", TRANSITION, []);
crate::ros_message!(
    TransitionDescription,
    "lifecycle_msgs",
    "TransitionDescription",
    "Transition transition\nState start_state\nState goal_state\n",
    [Transition, State]
);
crate::ros_message!(
    TransitionEvent,
    "lifecycle_msgs",
    "TransitionEvent",
    "uint64 timestamp\nTransition transition\nState start_state\nState goal_state\n",
    [Transition, State]
);
crate::ros_message!(
    ChangeStateRequest,
    "lifecycle_msgs",
    "ChangeState_Request",
    "Transition transition\n",
    [Transition]
);
crate::ros_message!(
    ChangeStateResponse,
    "lifecycle_msgs",
    "ChangeState_Response",
    "bool success\n",
    []
);
crate::ros_message!(
    EmptyRequest,
    "lifecycle_msgs",
    "GetState_Request",
    "uint8 structure_needs_at_least_one_member\n",
    []
);
crate::ros_message!(
    GetStateResponse,
    "lifecycle_msgs",
    "GetState_Response",
    "State current_state\n",
    [State]
);
crate::ros_message!(
    GetAvailableStatesResponse,
    "lifecycle_msgs",
    "GetAvailableStates_Response",
    "State[] available_states\n",
    [State]
);
crate::ros_message!(
    GetAvailableTransitionsResponse,
    "lifecycle_msgs",
    "GetAvailableTransitions_Response",
    "TransitionDescription[] available_transitions\n",
    [TransitionDescription, Transition, State]
);
