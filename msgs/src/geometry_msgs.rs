//! `geometry_msgs/msg/{Point, Quaternion, Pose, PoseStamped, Vector3, Transform,
//! TransformStamped}`: the standard views of the TCP (RViz, Foxglove, PlotJuggler read them
//! without rpkm's package). SI: m, unit quaternions.

use serde::{Deserialize, Serialize};

use crate::{builtin_interfaces::Time, std_msgs::Header};

/// `geometry_msgs/msg/Point`: a position (m).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Point {
    /// `float64 x` (m).
    pub x: f64,
    /// `float64 y` (m).
    pub y: f64,
    /// `float64 z` (m).
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`: an orientation, (x, y, z, w) with w the scalar part.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// `float64 x 0`.
    pub x: f64,
    /// `float64 y 0`.
    pub y: f64,
    /// `float64 z 0`.
    pub z: f64,
    /// `float64 w 1`.
    pub w: f64,
}

impl Default for Quaternion {
    /// The identity, as the `.msg` defaults say.
    fn default() -> Self {
        Self::about_z(0.0)
    }
}

impl Quaternion {
    /// A rotation by `angle` (rad) about z: a planar machine's platform angle ψ is a yaw.
    pub fn about_z(angle: f64) -> Self {
        let (s, c) = (0.5 * angle).sin_cos();
        Self {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }
}

/// `geometry_msgs/msg/Pose`: position and orientation.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    /// `Point position`.
    pub position: Point,
    /// `Quaternion orientation`.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`: a pose in a frame at a time.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PoseStamped {
    /// `std_msgs/Header header`.
    pub header: Header,
    /// `Pose pose`.
    pub pose: Pose,
}

/// `geometry_msgs/msg/Vector3`: a free vector (m for a translation).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vector3 {
    /// `float64 x`.
    pub x: f64,
    /// `float64 y`.
    pub y: f64,
    /// `float64 z`.
    pub z: f64,
}

/// `geometry_msgs/msg/Transform`: translation and rotation of a child frame in its parent.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Transform {
    /// `Vector3 translation` (m).
    pub translation: Vector3,
    /// `Quaternion rotation`.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`: `child_frame_id` in `header.frame_id` at
/// `header.stamp`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TransformStamped {
    /// `std_msgs/Header header`: the parent frame and the time.
    pub header: Header,
    /// `string child_frame_id`.
    pub child_frame_id: String,
    /// `Transform transform`.
    pub transform: Transform,
}

/// The `.msg` text of `geometry_msgs/msg/Point`.
pub const POINT_MSG: &str = "\
# This contains the position of a point in free space
float64 x
float64 y
float64 z
";

/// The `.msg` text of `geometry_msgs/msg/Quaternion`.
pub const QUATERNION_MSG: &str = "\
# This represents an orientation in free space in quaternion form.

float64 x 0
float64 y 0
float64 z 0
float64 w 1
";

/// The `.msg` text of `geometry_msgs/msg/Pose`.
pub const POSE_MSG: &str = "\
# A representation of pose in free space, composed of position and orientation.

Point position
Quaternion orientation
";

/// The `.msg` text of `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED_MSG: &str = "\
# A Pose with reference coordinate frame and timestamp

std_msgs/Header header
Pose pose
";

/// The `.msg` text of `geometry_msgs/msg/Vector3`.
pub const VECTOR3_MSG: &str = "\
# This represents a vector in free space.

# This is semantically different than a point.
# A vector is always anchored at the origin.
# When a transform is applied to a vector, only the rotational component is applied.

float64 x
float64 y
float64 z
";

/// The `.msg` text of `geometry_msgs/msg/Transform`.
pub const TRANSFORM_MSG: &str = "\
# This represents the transform between two coordinate frames in free space.

Vector3 translation
Quaternion rotation
";

/// The `.msg` text of `geometry_msgs/msg/TransformStamped`.
pub const TRANSFORM_STAMPED_MSG: &str = "\
# This expresses a transform from coordinate frame header.frame_id
# to the coordinate frame child_frame_id at the time of header.stamp
#
# This message is mostly used by the
# <a href=\"https://docs.ros.org/en/rolling/p/tf2/\">tf2</a> package.
# See its documentation for more information.
#
# The child_frame_id is necessary in addition to the frame_id
# in the Header to communicate the full reference for the transform
# in a self contained message.

# The frame id in the header is used as the reference frame of this transform.
std_msgs/Header header

# The frame id of the child frame to which this transform points.
string child_frame_id

# Translation and rotation in 3-dimensions of child_frame_id from header.frame_id.
Transform transform
";

crate::ros_message!(Point, "geometry_msgs", "Point", POINT_MSG, []);
crate::ros_message!(
    Quaternion,
    "geometry_msgs",
    "Quaternion",
    QUATERNION_MSG,
    []
);
crate::ros_message!(Pose, "geometry_msgs", "Pose", POSE_MSG, [Point, Quaternion]);
crate::ros_message!(
    PoseStamped,
    "geometry_msgs",
    "PoseStamped",
    POSE_STAMPED_MSG,
    [Header, Time, Pose, Point, Quaternion]
);
crate::ros_message!(Vector3, "geometry_msgs", "Vector3", VECTOR3_MSG, []);
crate::ros_message!(
    Transform,
    "geometry_msgs",
    "Transform",
    TRANSFORM_MSG,
    [Vector3, Quaternion]
);
crate::ros_message!(
    TransformStamped,
    "geometry_msgs",
    "TransformStamped",
    TRANSFORM_STAMPED_MSG,
    [Header, Time, Transform, Vector3, Quaternion]
);
