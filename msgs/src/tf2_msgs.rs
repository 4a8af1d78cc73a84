//! `tf2_msgs/msg/TFMessage`: the message of `/tf`.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::geometry_msgs::{Quaternion, Transform, TransformStamped, Vector3};
use crate::std_msgs::Header;

/// `tf2_msgs/msg/TFMessage`: transforms published together.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TfMessage {
    /// `geometry_msgs/TransformStamped[] transforms`.
    pub transforms: Vec<TransformStamped>,
}

/// The `.msg` text of `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE_MSG: &str = "\
geometry_msgs/TransformStamped[] transforms
";

crate::ros_message!(
    TfMessage,
    "tf2_msgs",
    "TFMessage",
    TF_MESSAGE_MSG,
    [
        TransformStamped,
        Header,
        Time,
        Transform,
        Vector3,
        Quaternion
    ]
);
