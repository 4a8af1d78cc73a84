//! The offered QoS profile recorded per topic, in rosbag2's YAML form.

use std::fmt::Write as _;

/// History policy (rosbag2 writes the `rmw_qos_history_policy_t` value).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum History {
    /// `KEEP_LAST` (1), with [`QosProfile::depth`].
    KeepLast,
    /// `KEEP_ALL` (2).
    KeepAll,
}

/// Reliability policy of a recorded topic (rosbag2 offered QoS).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BagReliability {
    /// `RELIABLE` (1).
    Reliable,
    /// `BEST_EFFORT` (2).
    BestEffort,
}

/// Durability policy of a recorded topic (rosbag2 offered QoS).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BagDurability {
    /// `TRANSIENT_LOCAL` (1).
    TransientLocal,
    /// `VOLATILE` (2).
    Volatile,
}

/// Liveliness policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Liveliness {
    /// `AUTOMATIC` (1).
    Automatic,
    /// `MANUAL_BY_TOPIC` (3).
    ManualByTopic,
}

/// The QoS a topic's publisher offered, stored with the topic in the bag (channel metadata
/// `offered_qos_profiles` and `metadata.yaml`), so that a replay can offer the same.
///
/// Durations are `None` for "infinite", written as rosbag2 does (`sec: 9223372036`,
/// `nsec: 854775807`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QosProfile {
    pub history: History,
    /// Queue depth for [`History::KeepLast`].
    pub depth: u32,
    pub reliability: BagReliability,
    pub durability: BagDurability,
    /// Deadline in ns, `None` = infinite.
    pub deadline_ns: Option<u64>,
    /// Lifespan in ns, `None` = infinite.
    pub lifespan_ns: Option<u64>,
    pub liveliness: Liveliness,
    /// Liveliness lease duration in ns, `None` = infinite.
    pub liveliness_lease_duration_ns: Option<u64>,
    pub avoid_ros_namespace_conventions: bool,
}

impl Default for QosProfile {
    /// ROS 2's default for topics: keep last 10, reliable, volatile.
    fn default() -> Self {
        Self {
            history: History::KeepLast,
            depth: 10,
            reliability: BagReliability::Reliable,
            durability: BagDurability::Volatile,
            deadline_ns: None,
            lifespan_ns: None,
            liveliness: Liveliness::Automatic,
            liveliness_lease_duration_ns: None,
            avoid_ros_namespace_conventions: false,
        }
    }
}

impl QosProfile {
    /// ROS 2's sensor-data profile: keep last 5, best effort, volatile.
    pub fn sensor_data() -> Self {
        Self {
            depth: 5,
            reliability: BagReliability::BestEffort,
            ..Self::default()
        }
    }

    /// The list holding this one profile, as the YAML string rosbag2 stores in
    /// `offered_qos_profiles` for metadata version 8 and in the MCAP channel metadata
    /// (rosbag2_storage's `serialize_rclcpp_qos_vector` with version 8): enum values as the
    /// rmw integers (the only form Iron's player decodes; Jazzy's reads these and rmw's
    /// names), infinite durations as `9223372036 s 854775807 ns` (`RMW_DURATION_INFINITE`).
    pub fn to_rosbag2_yaml(&self) -> String {
        let history = match self.history {
            History::KeepLast => 1,
            History::KeepAll => 2,
        };
        let reliability = match self.reliability {
            BagReliability::Reliable => 1,
            BagReliability::BestEffort => 2,
        };
        let durability = match self.durability {
            BagDurability::TransientLocal => 1,
            BagDurability::Volatile => 2,
        };
        let liveliness = match self.liveliness {
            Liveliness::Automatic => 1,
            Liveliness::ManualByTopic => 3,
        };
        let mut out = String::new();
        // Writing into a String cannot fail.
        let _ = write!(
            out,
            "- history: {history}\n  depth: {}\n  reliability: {reliability}\n  durability: \
             {durability}\n",
            self.depth
        );
        write_duration(&mut out, "deadline", self.deadline_ns);
        write_duration(&mut out, "lifespan", self.lifespan_ns);
        let _ = writeln!(out, "  liveliness: {liveliness}");
        write_duration(
            &mut out,
            "liveliness_lease_duration",
            self.liveliness_lease_duration_ns,
        );
        let _ = write!(
            out,
            "  avoid_ros_namespace_conventions: {}",
            self.avoid_ros_namespace_conventions
        );
        out
    }
}

/// `rmw`'s infinite duration as rosbag2 writes it.
const INFINITE_SEC: u64 = 9_223_372_036;
const INFINITE_NSEC: u64 = 854_775_807;

fn write_duration(out: &mut String, key: &str, ns: Option<u64>) {
    let (sec, nsec) = match ns {
        Some(ns) => (ns / 1_000_000_000, ns % 1_000_000_000),
        None => (INFINITE_SEC, INFINITE_NSEC),
    };
    let _ = write!(out, "  {key}:\n    sec: {sec}\n    nsec: {nsec}\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_profile_yaml_is_rosbag2_layout() {
        let yaml = QosProfile::default().to_rosbag2_yaml();
        let expected = "- history: 1\n  depth: 10\n  reliability: 1\n  durability: 2\n  \
                        deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    \
                        sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  \
                        liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  \
                        avoid_ros_namespace_conventions: false";
        assert_eq!(yaml, expected);
        let parsed: serde_yaml::Value = serde_yaml::from_str(&yaml).expect("valid YAML");
        assert_eq!(parsed[0]["depth"].as_u64(), Some(10));
    }

    #[test]
    fn finite_durations_split_into_sec_and_nsec() {
        let qos = QosProfile {
            deadline_ns: Some(1_500_000_000),
            ..QosProfile::sensor_data()
        };
        let parsed: serde_yaml::Value =
            serde_yaml::from_str(&qos.to_rosbag2_yaml()).expect("valid YAML");
        assert_eq!(parsed[0]["deadline"]["sec"].as_u64(), Some(1));
        assert_eq!(parsed[0]["deadline"]["nsec"].as_u64(), Some(500_000_000));
        assert_eq!(parsed[0]["reliability"].as_u64(), Some(2));
    }
}
