//! ROS 2 messages of rpkm (`rpkm_msgs`) and the standard ones the nodes use.
//!
//! Every message type carries its ROS 2 identity through [`RosMessage`]: the type name
//! (`rpkm_msgs/msg/ActuatorState`) and the `.msg` definition text, so that the DDS
//! transport and the MCAP recorder (schema encoding `ros2msg`) describe it the same way.
//! Units on every topic are SI (m, rad, N, s) per REP 103; the core's mm are converted at
//! this boundary only.
//!
//! The Rust field order of every type is the `.msg` field order, so that serde through
//! [`to_cdr`] / [`from_cdr`] (or ros2-client) produces exactly the ROS 2 (XCDR1, little
//! endian) wire layout. The hot-path types ([`ActuatorState`], [`TcpEstimate`] and their
//! [`Time`]) are also fixed-size `#[repr(C)]`; with the cargo feature `zero-copy` they derive
//! iceoryx2's `ZeroCopySend` and can be moved through shared memory without copies.

pub mod actuator_state;
pub mod builtin_interfaces;
pub mod calibrate_action;
pub mod calibration_srv;
pub mod campaign_info;
pub mod cdr;
pub mod diagnosis;
pub mod diagnosis_candidate;
pub mod diagnostic_msgs;
pub mod geometry_msgs;
pub mod lifecycle_msgs;
pub mod parameters;
pub mod preload_status;
pub mod sensor_msgs;
pub mod std_msgs;
pub mod tcp_estimate;
pub mod tcp_measurement;
pub mod tf2_msgs;

pub use actuator_state::ActuatorState;
pub use builtin_interfaces::Time;
pub use campaign_info::CampaignInfo;
pub use cdr::{from_cdr, to_cdr, CdrError, CDR_LE_HEADER};
pub use diagnosis::Diagnosis;
pub use diagnosis_candidate::DiagnosisCandidate;
pub use diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
pub use geometry_msgs::{
    Point, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Vector3,
};
pub use parameters::Parameters;
pub use preload_status::{PreloadLevel, PreloadStatus};
pub use sensor_msgs::{JointState, Temperature};
pub use std_msgs::Header;
pub use tcp_estimate::TcpEstimate;
pub use tcp_measurement::{InstrumentId, TcpMeasurement, UnknownInstrument};
pub use tf2_msgs::TfMessage;

/// Package name of the project's own messages.
pub const PACKAGE: &str = "rpkm_msgs";

/// A ROS 2 message: serde (CDR) serialisable, with its ROS type name and definition.
pub trait RosMessage:
    serde::Serialize + serde::de::DeserializeOwned + Clone + Send + 'static
{
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
    /// `pkg::msg::dds_::Name_`, the type name ROS 2 registers with DDS.
    fn dds_type_name() -> String {
        format!("{}::msg::dds_::{}_", Self::PACKAGE, Self::NAME)
    }
}

/// The `.msg` text of one type, without its dependencies.
pub trait MsgText {
    /// `pkg/msg/Name`.
    const FULL_NAME: &'static str;
    /// The `.msg` file content.
    const TEXT: &'static str;
}

/// Builds a rosbag2-style definition: `own` followed by every dependency as
/// `"=" * 80`, `MSG: pkg/msg/Type`, text. `deps` lists (full name, text) of all transitive
/// dependencies, each once.
pub fn compose_definition(own: &str, deps: &[(&str, &str)]) -> String {
    let mut out = String::from(own.trim_end());
    out.push('\n');
    for (name, text) in deps {
        out.push_str(&"=".repeat(80));
        out.push_str("\nMSG: ");
        out.push_str(name);
        out.push('\n');
        out.push_str(text.trim_end());
        out.push('\n');
    }
    out
}

/// Implements [`MsgText`] and [`RosMessage`] for a type; `deps` are the [`MsgText`] types of
/// all transitive dependencies, each once.
macro_rules! ros_message {
    ($ty:ty, $pkg:literal, $name:literal, $text:expr, [$($dep:ty),* $(,)?]) => {
        impl $crate::MsgText for $ty {
            const FULL_NAME: &'static str = concat!($pkg, "/msg/", $name);
            const TEXT: &'static str = $text;
        }
        impl $crate::RosMessage for $ty {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
            fn definition() -> String {
                $crate::compose_definition(
                    <$ty as $crate::MsgText>::TEXT,
                    &[$((<$dep as $crate::MsgText>::FULL_NAME, <$dep as $crate::MsgText>::TEXT)),*],
                )
            }
        }
    };
}
pub(crate) use ros_message;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert_eq!(ActuatorState::type_name(), "rpkm_msgs/msg/ActuatorState");
        assert_eq!(
            ActuatorState::dds_type_name(),
            "rpkm_msgs::msg::dds_::ActuatorState_"
        );
        assert_eq!(
            DiagnosticArray::type_name(),
            "diagnostic_msgs/msg/DiagnosticArray"
        );
    }

    #[test]
    fn standard_views_carry_their_ros_names() {
        assert_eq!(
            PoseStamped::dds_type_name(),
            "geometry_msgs::msg::dds_::PoseStamped_"
        );
        assert_eq!(
            TfMessage::dds_type_name(),
            "tf2_msgs::msg::dds_::TFMessage_"
        );
        assert_eq!(JointState::type_name(), "sensor_msgs/msg/JointState");
        assert_eq!(
            Temperature::dds_type_name(),
            "sensor_msgs::msg::dds_::Temperature_"
        );
        let def = TfMessage::definition();
        for dep in [
            "geometry_msgs/msg/TransformStamped",
            "std_msgs/msg/Header",
            "builtin_interfaces/msg/Time",
            "geometry_msgs/msg/Transform",
            "geometry_msgs/msg/Vector3",
            "geometry_msgs/msg/Quaternion",
        ] {
            assert!(def.contains(&format!("MSG: {dep}\n")), "{dep} missing");
        }
    }

    #[test]
    fn a_yaw_quaternion_rotates_x_by_the_angle() {
        // v' = q v q*: for q = (0, 0, z, w) the image of (1, 0, 0) is
        // (w² − z², 2wz, 0), which must be (cos ψ, sin ψ, 0).
        for psi in [0.3, -2.5, std::f64::consts::PI] {
            let q = Quaternion::about_z(psi);
            let (w, z) = (q.w, q.z);
            assert!((w * w - z * z - psi.cos()).abs() < 1e-15, "{psi}");
            assert!((2.0 * w * z - psi.sin()).abs() < 1e-15, "{psi}");
            assert!((w * w + z * z - 1.0).abs() < 1e-15);
        }
    }

    #[test]
    fn definitions_list_their_dependencies() {
        let def = Diagnosis::definition();
        assert!(def.starts_with("# Result of the model diagnosis"));
        assert!(def.contains(&format!(
            "{}\nMSG: rpkm_msgs/msg/DiagnosisCandidate\n",
            "=".repeat(80)
        )));
        let def = DiagnosticArray::definition();
        for dep in [
            "std_msgs/msg/Header",
            "builtin_interfaces/msg/Time",
            "diagnostic_msgs/msg/DiagnosticStatus",
            "diagnostic_msgs/msg/KeyValue",
        ] {
            assert!(def.contains(&format!("MSG: {dep}\n")), "{dep} missing");
        }
        assert!(ActuatorState::definition()
            .contains("MSG: builtin_interfaces/msg/Time\n# This message communicates ROS Time"));
        assert!(!Time::definition().contains("MSG:"));
    }
}
