//! `sensor_msgs/msg/JointState`: the drives as joints (RViz, PlotJuggler, robot_state_publisher).

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::std_msgs::Header;

/// `sensor_msgs/msg/JointState`: named joints with position, velocity and effort; the arrays
/// are either empty or as long as `name`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct JointState {
    /// `std_msgs/Header header`.
    pub header: Header,
    /// `string[] name`.
    pub name: Vec<String>,
    /// `float64[] position`: m for a prismatic joint.
    pub position: Vec<f64>,
    /// `float64[] velocity`: m/s; empty when not known.
    pub velocity: Vec<f64>,
    /// `float64[] effort`: N for a prismatic joint.
    pub effort: Vec<f64>,
}

/// The `.msg` text of `sensor_msgs/msg/JointState`.
pub const JOINT_STATE_MSG: &str = "\
# This is a message that holds data to describe the state of a set of torque controlled joints.
#
# The state of each joint (revolute or prismatic) is defined by:
#  * the position of the joint (rad or m),
#  * the velocity of the joint (rad/s or m/s) and
#  * the effort that is applied in the joint (Nm or N).
#
# Each joint is uniquely identified by its name
# The header specifies the time at which the joint states were recorded. All the joint states
# in one message have to be recorded at the same time.
#
# This message consists of a multiple arrays, one for each part of the joint state.
# The goal is to make each of the fields optional. When e.g. your joints have no
# effort associated with them, you can leave the effort array empty.
#
# All arrays in this message should have the same size, or be empty.
# This is the only way to uniquely associate the joint name with the correct
# states.

std_msgs/Header header

string[] name
float64[] position
float64[] velocity
float64[] effort
";

crate::ros_message!(
    JointState,
    "sensor_msgs",
    "JointState",
    JOINT_STATE_MSG,
    [Header, Time]
);

/// `sensor_msgs/msg/Temperature`: one thermometer's reading.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Temperature {
    /// `std_msgs/Header header`: when and where the temperature was measured.
    pub header: Header,
    /// `float64 temperature`: °C.
    pub temperature: f64,
    /// `float64 variance`: °C²; 0 is "unknown".
    pub variance: f64,
}

/// The `.msg` text of `sensor_msgs/msg/Temperature`.
pub const TEMPERATURE_MSG: &str = "\
# Single temperature reading.

std_msgs/Header header # timestamp is the time the temperature was measured
                             # frame_id is the location of the temperature reading

float64 temperature     # Measurement of the Temperature in Degrees Celsius.

float64 variance        # 0 is interpreted as variance unknown.
";

crate::ros_message!(
    Temperature,
    "sensor_msgs",
    "Temperature",
    TEMPERATURE_MSG,
    [Header, Time]
);
