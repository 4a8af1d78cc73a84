//! rosbag2's `metadata.yaml`.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::{BagOpenError, BagWriteError};

/// The `metadata.yaml` version written: 8, the newest one that `ros2 bag` on both Iron and
/// Jazzy reads (ros2/rosbag2, rosbag2_storage/include/rosbag2_storage/yaml.hpp,
/// `convert<BagMetadata>::decode` on branches iron and jazzy). Jazzy itself writes 9, where
/// `offered_qos_profiles` is a YAML sequence with rmw's policy names; Iron reads that key
/// `as<std::string>()` from version 4 on and refuses the sequence. In version 8 it is a YAML
/// string whose profiles give the policies as integers (Iron's player decodes nothing else;
/// Jazzy's decoder accepts both forms). Versions 6 to 8 require `custom_data`, 7 and 8
/// `type_description_hash`, 8 `ros_distro` (Jazzy). rosbags 0.11 accepts 4 to 9.
/// tests/it/bag_rosbag2_metadata.rs holds every bag rpkm writes to these rules.
pub const METADATA_VERSION: u32 = 8;

/// File name of the metadata in a bag folder.
pub(crate) const METADATA_FILE: &str = "metadata.yaml";

#[derive(Debug, Serialize, Deserialize)]
struct MetadataFile {
    rosbag2_bagfile_information: BagMetadata,
}

/// The contents of `metadata.yaml` (`rosbag2_bagfile_information`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BagMetadata {
    pub version: u32,
    pub storage_identifier: String,
    pub duration: Duration,
    pub starting_time: StartingTime,
    pub message_count: u64,
    pub topics_with_message_count: Vec<TopicWithMessageCount>,
    #[serde(default)]
    pub compression_format: String,
    #[serde(default)]
    pub compression_mode: String,
    pub relative_file_paths: Vec<String>,
    #[serde(default)]
    pub files: Vec<FileInformation>,
    /// Always written (rosbag2's reader requires the key from version 6 on: without it
    /// `ros2 bag info` stops at "invalid node; first invalid key: custom_data"); empty is
    /// written as null, as rosbag2 writes it. Absent in versions before 6.
    #[serde(default)]
    pub custom_data: Option<BTreeMap<String, String>>,
    /// rosbag2 writes `$ROS_DISTRO` of the recording process, empty when unset (`ros2 bag
    /// info` then shows "unknown"); rpkm runs on no ROS distribution and writes it empty.
    /// Absent before version 8.
    #[serde(default)]
    pub ros_distro: String,
}

/// Bag duration, last minus first log time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Duration {
    pub nanoseconds: u64,
}

/// First log time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct StartingTime {
    pub nanoseconds_since_epoch: u64,
}

/// One topic and its number of messages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopicWithMessageCount {
    pub topic_metadata: TopicMetadata,
    pub message_count: u64,
}

/// A topic's description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopicMetadata {
    pub name: String,
    /// `pkg/msg/Type`.
    #[serde(rename = "type")]
    pub type_name: String,
    pub serialization_format: String,
    /// The YAML string of [`QosProfile::to_rosbag2_yaml`](super::QosProfile::to_rosbag2_yaml)
    /// in versions 4 to 8 (written), a sequence of maps in version 9 (read), absent before 4.
    #[serde(default)]
    pub offered_qos_profiles: serde_yaml::Value,
    /// `RIHS01_...`, or empty where unknown (as rosbag2 writes a topic without one); absent
    /// before version 7.
    #[serde(default)]
    pub type_description_hash: String,
}

/// One storage file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileInformation {
    pub path: String,
    pub starting_time: StartingTime,
    pub duration: Duration,
    pub message_count: u64,
}

/// What the writer knows of one topic when it closes the bag.
pub(crate) struct TopicCount<'a> {
    pub name: &'a str,
    pub type_name: &'a str,
    pub qos_yaml: &'a str,
    pub type_hash: Option<&'a str>,
    pub count: u64,
}

impl BagMetadata {
    /// Metadata of a one-file MCAP bag. `time_bounds` are the first and last log times.
    pub(crate) fn for_single_file(
        file_name: &str,
        topics: &[TopicCount<'_>],
        time_bounds: Option<(u64, u64)>,
    ) -> Self {
        let (start, end) = time_bounds.unwrap_or((0, 0));
        let duration = Duration {
            nanoseconds: end.saturating_sub(start),
        };
        let starting_time = StartingTime {
            nanoseconds_since_epoch: start,
        };
        let message_count = topics.iter().map(|t| t.count).sum();
        Self {
            version: METADATA_VERSION,
            storage_identifier: super::format::STORAGE_IDENTIFIER.to_owned(),
            duration,
            starting_time,
            message_count,
            topics_with_message_count: topics
                .iter()
                .map(|t| TopicWithMessageCount {
                    topic_metadata: TopicMetadata {
                        name: t.name.to_owned(),
                        type_name: t.type_name.to_owned(),
                        serialization_format: super::format::MESSAGE_ENCODING.to_owned(),
                        offered_qos_profiles: serde_yaml::Value::String(t.qos_yaml.to_owned()),
                        type_description_hash: t.type_hash.unwrap_or_default().to_owned(),
                    },
                    message_count: t.count,
                })
                .collect(),
            // MCAP compresses chunks inside the storage: no rosbag2-level compression.
            compression_format: String::new(),
            compression_mode: String::new(),
            relative_file_paths: vec![file_name.to_owned()],
            files: vec![FileInformation {
                path: file_name.to_owned(),
                starting_time,
                duration,
                message_count,
            }],
            custom_data: None,
            ros_distro: String::new(),
        }
    }

    /// Writes `dir/metadata.yaml` through a temporary file and a rename.
    pub(crate) fn write_to(&self, dir: &Path) -> Result<(), BagWriteError> {
        let path = dir.join(METADATA_FILE);
        let text = serde_yaml::to_string(&MetadataFile {
            rosbag2_bagfile_information: self.clone(),
        })
        .map_err(|source| BagWriteError::Metadata {
            path: path.clone(),
            source,
        })?;
        let tmp = dir.join("metadata.yaml.tmp");
        std::fs::write(&tmp, text).map_err(|source| BagWriteError::Io {
            path: tmp.clone(),
            source,
        })?;
        std::fs::rename(&tmp, &path).map_err(|source| BagWriteError::Io { path, source })
    }

    /// Reads `dir/metadata.yaml`.
    pub fn read_from(dir: &Path) -> Result<Self, BagOpenError> {
        let path = dir.join(METADATA_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| BagOpenError::Io {
            path: path.clone(),
            source,
        })?;
        let file: MetadataFile = serde_yaml::from_str(&text)
            .map_err(|source| BagOpenError::Metadata { path, source })?;
        Ok(file.rosbag2_bagfile_information)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_file_metadata_round_trips_through_yaml() {
        let qos = super::super::QosProfile::default().to_rosbag2_yaml();
        let topics = [TopicCount {
            name: "/a",
            type_name: "rpkm_msgs/msg/ActuatorState",
            qos_yaml: &qos,
            type_hash: None,
            count: 3,
        }];
        let meta = BagMetadata::for_single_file("b_0.mcap", &topics, Some((100, 350)));
        assert_eq!(meta.duration.nanoseconds, 250);
        assert_eq!(meta.message_count, 3);
        let dir = tempfile::tempdir().expect("tempdir");
        meta.write_to(dir.path()).expect("writes");
        let back = BagMetadata::read_from(dir.path()).expect("reads");
        assert_eq!(back, meta);
        let text = std::fs::read_to_string(dir.path().join(METADATA_FILE)).expect("text");
        assert!(text.starts_with("rosbag2_bagfile_information:\n  version: 8\n"));
        assert!(
            text.contains("\n  custom_data: null\n  ros_distro: ''\n"),
            "{text}"
        );
    }

    fn parse(text: &str) -> BagMetadata {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join(METADATA_FILE), text).expect("write");
        BagMetadata::read_from(dir.path()).expect("reads")
    }

    /// A version-9 file in the layout Jazzy's encoder writes (yaml.hpp and qos.cpp encode()).
    const JAZZY_V9: &str = r#"rosbag2_bagfile_information:
  version: 9
  storage_identifier: mcap
  duration:
    nanoseconds: 5
  starting_time:
    nanoseconds_since_epoch: 7
  message_count: 2
  topics_with_message_count:
    - topic_metadata:
        name: /chatter
        type: std_msgs/msg/String
        serialization_format: cdr
        offered_qos_profiles:
          - history: keep_last
            depth: 7
            reliability: best_effort
            durability: transient_local
            deadline:
              sec: 9223372036
              nsec: 854775807
            lifespan:
              sec: 9223372036
              nsec: 854775807
            liveliness: automatic
            liveliness_lease_duration:
              sec: 9223372036
              nsec: 854775807
            avoid_ros_namespace_conventions: false
        type_description_hash: RIHS01_abc
      message_count: 2
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - b_0.mcap
  files:
    - path: b_0.mcap
      starting_time:
        nanoseconds_since_epoch: 7
      duration:
        nanoseconds: 5
      message_count: 2
  custom_data:
    operator: anna
  ros_distro: jazzy
"#;

    #[test]
    fn reads_the_version_9_layout_of_jazzy() {
        let meta = parse(JAZZY_V9);
        assert_eq!(meta.version, 9);
        let topic = &meta.topics_with_message_count[0].topic_metadata;
        assert_eq!(
            topic.offered_qos_profiles[0]["reliability"].as_str(),
            Some("best_effort")
        );
        assert_eq!(topic.offered_qos_profiles[0]["depth"].as_u64(), Some(7));
        assert_eq!(topic.type_description_hash, "RIHS01_abc");
        assert_eq!(meta.files[0].duration.nanoseconds, 5);
        let custom = meta.custom_data.expect("custom_data");
        assert_eq!(custom.get("operator").map(String::as_str), Some("anna"));
        assert_eq!(meta.ros_distro, "jazzy");
    }

    /// Version 4 (Foxy): no files, custom_data, type_description_hash or ros_distro yet.
    const FOXY_V4: &str = r#"rosbag2_bagfile_information:
  version: 4
  storage_identifier: sqlite3
  relative_file_paths:
    - b_0.db3
  duration:
    nanoseconds: 3
  starting_time:
    nanoseconds_since_epoch: 1
  message_count: 1
  topics_with_message_count:
    - topic_metadata:
        name: /a
        type: std_msgs/msg/Empty
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: 1
  compression_format: ""
  compression_mode: ""
"#;

    #[test]
    fn reads_the_version_4_layout_of_foxy() {
        let meta = parse(FOXY_V4);
        assert_eq!(meta.version, 4);
        assert_eq!(meta.relative_file_paths, ["b_0.db3"]);
        assert!(meta.files.is_empty() && meta.custom_data.is_none() && meta.ros_distro.is_empty());
        let topic = &meta.topics_with_message_count[0].topic_metadata;
        assert_eq!(topic.offered_qos_profiles.as_str(), Some(""));
        assert!(topic.type_description_hash.is_empty());
    }
}
