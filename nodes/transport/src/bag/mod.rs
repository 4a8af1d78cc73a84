//! MCAP bags in the rosbag2 layout: `<name>/metadata.yaml` next to `<name>/<name>_0.mcap`.
//!
//! - [`BagWriter`] records typed messages ([`RosMessage`](rpkm_msgs::RosMessage), CDR) or
//!   already-serialised CDR payloads (the recorder's raw path). The file is chunked and every
//!   chunk is handed to the operating system as soon as it is full, so a recorder killed with
//!   SIGKILL loses at most the open chunk; [`recover`] turns such a folder back into a valid bag.
//! - [`BagReader`] opens a bag folder or a bare `.mcap`, checks it, lists its topics and yields
//!   messages in log-time order, reading each chunk when its turn comes (memory: about a chunk,
//!   not the bag); [`BagMessage::decode`] decodes one into its Rust type.
//!
//! What readers outside Rust need and get (see `tests/python/bag_check.py`): MCAP header profile
//! `ros2`, one schema per type (encoding `ros2msg`, the `.msg` text with its dependencies), one
//! channel per topic (message encoding `cdr`, metadata `offered_qos_profiles` as the YAML string
//! rosbag2 writes), and a rosbag2 `metadata.yaml` of version [`METADATA_VERSION`] (rosbags 0.11
//! accepts 4 to 9).

mod cdr;
mod error;
mod format;
mod merge;
mod metadata;
mod qos;
mod reader;
mod records;
mod recover;
mod writer;

pub use cdr::{decode_cdr, encode_cdr};
pub use error::{
    BagDecodeError, BagOpenError, BagReadError, BagWriteError, CdrError, RecoverError,
};
pub use format::{
    MESSAGE_ENCODING, PROFILE, QOS_METADATA_KEY, SCHEMA_ENCODING, STORAGE_IDENTIFIER,
    TYPE_HASH_METADATA_KEY,
};
pub use merge::Messages;
pub use metadata::{BagMetadata, METADATA_VERSION};
pub use qos::{BagDurability, BagReliability, History, Liveliness, QosProfile};
pub use reader::{BagMessage, BagReader, TopicInfo};
pub use recover::{recover, FileRecovery, RecoveryReport, StopReason};
pub use writer::{
    BagCompression, BagSummary, BagWriter, BagWriterOptions, RawTopic, RawTopicHandle, TopicHandle,
};
