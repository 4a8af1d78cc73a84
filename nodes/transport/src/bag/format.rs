//! The names a ROS 2 MCAP bag carries: its profile, encodings and metadata keys.

/// MCAP header profile of ROS 2 bags.
pub const PROFILE: &str = "ros2";
/// Schema encoding of ROS 2 `.msg` definitions.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// Message encoding of CDR payloads.
pub const MESSAGE_ENCODING: &str = "cdr";
/// `storage_identifier` in `metadata.yaml`.
pub const STORAGE_IDENTIFIER: &str = "mcap";
/// Channel metadata key holding the offered QoS profiles (YAML string), as rosbag2 writes it.
pub const QOS_METADATA_KEY: &str = "offered_qos_profiles";
/// Channel metadata key holding the type description hash (`RIHS01_...`), when known.
pub const TYPE_HASH_METADATA_KEY: &str = "topic_type_hash";
