//! `diagnostic_msgs/msg/{DiagnosticArray, DiagnosticStatus, KeyValue}`.

use serde::{Deserialize, Serialize};

use crate::{builtin_interfaces::Time, std_msgs::Header};

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct KeyValue {
    /// `string key`: what the value is.
    pub key: String,
    /// `string value`: the value.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`: state of one component.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// `byte level`: one of [`DiagnosticStatus::OK`] .. [`DiagnosticStatus::STALE`].
    pub level: u8,
    /// `string name`: description of the test/component reporting.
    pub name: String,
    /// `string message`: description of the status.
    pub message: String,
    /// `string hardware_id`: hardware unique string.
    pub hardware_id: String,
    /// `KeyValue[] values`: additional values.
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    /// `byte OK=0`.
    pub const OK: u8 = 0;
    /// `byte WARN=1`.
    pub const WARN: u8 = 1;
    /// `byte ERROR=2`.
    pub const ERROR: u8 = 2;
    /// `byte STALE=3`.
    pub const STALE: u8 = 3;
}

/// `diagnostic_msgs/msg/DiagnosticArray`: the statuses of several components.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// `std_msgs/Header header`.
    pub header: Header,
    /// `DiagnosticStatus[] status`.
    pub status: Vec<DiagnosticStatus>,
}

/// The `.msg` text of `diagnostic_msgs/msg/KeyValue`.
pub const KEY_VALUE_MSG: &str = "\
# What to label this value when viewing.
string key
# A value to track over time.
string value
";

/// The `.msg` text of `diagnostic_msgs/msg/DiagnosticStatus`.
pub const DIAGNOSTIC_STATUS_MSG: &str = "\
# This message holds the status of an individual component of the robot.

# Possible levels of operations.
byte OK=0
byte WARN=1
byte ERROR=2
byte STALE=3

# Level of operation enumerated above.
byte level
# A description of the test/component reporting.
string name
# A description of the status.
string message
# A hardware unique string.
string hardware_id
# An array of values associated with the status.
KeyValue[] values
";

/// The `.msg` text of `diagnostic_msgs/msg/DiagnosticArray`.
pub const DIAGNOSTIC_ARRAY_MSG: &str = "\
# This message is used to send diagnostic information about the state of the robot.
std_msgs/Header header # for timestamp
DiagnosticStatus[] status # an array of components being reported on
";

crate::ros_message!(KeyValue, "diagnostic_msgs", "KeyValue", KEY_VALUE_MSG, []);
crate::ros_message!(
    DiagnosticStatus,
    "diagnostic_msgs",
    "DiagnosticStatus",
    DIAGNOSTIC_STATUS_MSG,
    [KeyValue]
);
crate::ros_message!(
    DiagnosticArray,
    "diagnostic_msgs",
    "DiagnosticArray",
    DIAGNOSTIC_ARRAY_MSG,
    [Header, Time, DiagnosticStatus, KeyValue]
);
