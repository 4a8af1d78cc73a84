//! ROS 2 messages of rpkm (`rpkm_msgs`) and the standard ones the nodes use.
//!
//! Every message type carries its ROS 2 identity through [`RosMessage`]: the type name
//! (`rpkm_msgs/msg/ActuatorState`) and the `.msg` definition text, so that the DDS
//! transport and the MCAP recorder (schema encoding `ros2msg`) describe it the same way.
//! Units on every topic are SI (m, rad, N, s) per REP 103; the core's mm are converted at
//! this boundary only.

/// A ROS 2 message: serde (CDR) serialisable, with its ROS type name and definition.
pub trait RosMessage: serde::Serialize + serde::de::DeserializeOwned + Clone + Send + 'static {
    /// Package name, e.g. `rpkm_msgs`.
    const PACKAGE: &'static str;
    /// Message name, e.g. `ActuatorState`.
    const NAME: &'static str;
    /// The `.msg` text of this type followed by the definitions of the non-primitive types
    /// it uses, in rosbag2's layout (a line of 80 `=`, then `MSG: pkg/msg/Type`, then its text).
    fn definition() -> String;
    /// `pkg/msg/Name`, the ROS 2 type name.
    fn type_name() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }
}
