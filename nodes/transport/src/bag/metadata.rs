//! rosbag2's `metadata.yaml`.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::{BagOpenError, BagWriteError};

/// The `metadata.yaml` version written. Version 8 stores `offered_qos_profiles` as a YAML string
/// and has `type_description_hash` and `ros_distro`; rosbags 0.11 accepts 4 to 9, not 10.
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
    /// written as null, as rosbag2 writes it.
    #[serde(default)]
    pub custom_data: Option<BTreeMap<String, String>>,
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
    /// A YAML string in versions up to 8, a list in version 9.
    #[serde(default)]
    pub offered_qos_profiles: serde_yaml::Value,
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
            storage_identifier: super::STORAGE_IDENTIFIER.to_owned(),
            duration,
            starting_time,
            message_count,
            topics_with_message_count: topics
                .iter()
                .map(|t| TopicWithMessageCount {
                    topic_metadata: TopicMetadata {
                        name: t.name.to_owned(),
                        type_name: t.type_name.to_owned(),
                        serialization_format: super::MESSAGE_ENCODING.to_owned(),
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
    }
}
