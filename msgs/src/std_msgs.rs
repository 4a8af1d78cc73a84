//! `std_msgs/msg/Header`.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;

/// `std_msgs/msg/Header`: stamp and coordinate frame of stamped data.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Header {
    /// `builtin_interfaces/Time stamp`: time of the data.
    pub stamp: Time,
    /// `string frame_id`: coordinate frame the data is in.
    pub frame_id: String,
}

/// The `.msg` text of `std_msgs/msg/Header`.
pub const HEADER_MSG: &str = "\
# Standard metadata for higher-level stamped data types.
# This is generally used to communicate timestamped data
# in a particular coordinate frame.

# Two-integer timestamp that is expressed as seconds and nanoseconds.
builtin_interfaces/Time stamp

# Transform frame with which this data is associated.
string frame_id
";

crate::ros_message!(Header, "std_msgs", "Header", HEADER_MSG, [Time]);
