//! Errors of the bag operations: one enum per operation, each naming the file, topic or record.

use std::path::PathBuf;

pub use super::cdr::CdrError;

/// Errors of [`BagWriter`](super::BagWriter).
#[derive(Debug, thiserror::Error)]
pub enum BagWriteError {
    /// The bag folder exists already; a bag is never overwritten.
    #[error("bag folder {path} exists already")]
    AlreadyExists { path: PathBuf },
    /// The bag name cannot be used as a folder and file name.
    #[error("bag path {path} has no usable final name (need a plain UTF-8 folder name)")]
    BadName { path: PathBuf },
    /// File system error.
    #[error("I/O error on {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("MCAP error writing {path}: {source}")]
    Mcap {
        path: PathBuf,
        source: mcap::McapError,
    },
    /// `metadata.yaml` could not be produced.
    #[error("cannot serialise {path}: {source}")]
    Metadata {
        path: PathBuf,
        source: serde_yaml::Error,
    },
    /// The topic was added before with another type.
    #[error("topic {topic} was added with type {existing}, not {requested}")]
    TopicTypeConflict {
        topic: String,
        existing: String,
        requested: String,
    },
    /// A handle from another writer.
    #[error("topic handle {index} does not belong to this bag writer")]
    ForeignHandle { index: usize },
    /// A message could not be serialised.
    #[error("cannot serialise {type_name} for topic {topic}: {source}")]
    Serialize {
        topic: String,
        type_name: String,
        source: CdrError,
    },
    /// More than 65535 schemas or channels, or sequence numbers exhausted.
    #[error("bag limit reached: {what}")]
    Limit { what: &'static str },
}

/// Errors of [`BagReader::open`](super::BagReader::open).
#[derive(Debug, thiserror::Error)]
pub enum BagOpenError {
    /// File system error.
    #[error("I/O error on {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// `metadata.yaml` is not valid rosbag2 metadata.
    #[error("invalid rosbag2 metadata {path}: {source}")]
    Metadata {
        path: PathBuf,
        source: serde_yaml::Error,
    },
    /// A folder without `metadata.yaml` nor any `.mcap` file.
    #[error("{path} is neither a rosbag2 folder nor an .mcap file")]
    NotABag { path: PathBuf },
    /// The metadata names another storage plugin.
    #[error("{path}: storage {storage:?} is not supported (only mcap)")]
    UnsupportedStorage { path: PathBuf, storage: String },
    /// The metadata names a file that is not there.
    #[error("{path}: file {file} named in metadata.yaml is missing")]
    MissingFile { path: PathBuf, file: String },
    /// The file does not start with the MCAP magic.
    #[error("{path} is not an MCAP file (bad magic)")]
    BadMagic { path: PathBuf },
    /// A record could not be parsed or a chunk is corrupt.
    #[error("{path}: corrupt record at byte {offset}: {source}")]
    Corrupt {
        path: PathBuf,
        offset: u64,
        source: mcap::McapError,
    },
    /// A message refers to a channel that was never defined.
    #[error("{path}: message at byte {offset} uses unknown channel {channel_id}")]
    UnknownChannel {
        path: PathBuf,
        offset: u64,
        channel_id: u16,
    },
    /// A channel id defined again for another topic (MCAP requires every definition of an id
    /// to be identical): its messages could not be told apart.
    #[error(
        "{path}: record at byte {offset} defines channel {channel_id} as {topic:?}, \
         which is already channel {channel_id} with another topic or type"
    )]
    ChannelRedefined {
        path: PathBuf,
        offset: u64,
        channel_id: u16,
        topic: String,
    },
    /// The file ends inside a record or lacks its end: its writer did not finish.
    #[error(
        "{path} ends at byte {offset} without its data end record: the writer did not finish; \
         use bag::recover to copy its complete chunks into a new bag"
    )]
    Truncated { path: PathBuf, offset: u64 },
}

/// Errors while iterating the messages of an open bag: the chunks are read again when their
/// turn comes, so a file changed or removed since [`BagReader::open`](super::BagReader::open)
/// checked it shows here.
#[derive(Debug, thiserror::Error)]
pub enum BagReadError {
    /// File system error.
    #[error("I/O error reading {path} at byte {offset}: {source}")]
    Io {
        path: PathBuf,
        offset: u64,
        source: std::io::Error,
    },
    /// The record no longer parses, or its chunk fails its CRC.
    #[error(
        "{path}: corrupt record at byte {offset} (the file changed since it was opened): {source}"
    )]
    Corrupt {
        path: PathBuf,
        offset: u64,
        source: mcap::McapError,
    },
    /// The record is not what the bag held when it was opened.
    #[error("{path}: record at byte {offset} changed since the bag was opened: {what}")]
    Changed {
        path: PathBuf,
        offset: u64,
        what: String,
    },
}

/// Errors of [`BagMessage::decode`](super::BagMessage::decode).
#[derive(Debug, thiserror::Error)]
pub enum BagDecodeError {
    /// The message's ROS type is not the requested Rust type's.
    #[error("topic {topic} (message {index}) has type {found}, not {expected}")]
    TypeMismatch {
        topic: String,
        index: usize,
        expected: String,
        found: String,
    },
    /// The payload is not a valid CDR value of the type.
    #[error(
        "topic {topic}, message {index} (log time {log_time} ns, {file} record at byte \
         {record_offset}): {source}"
    )]
    Cdr {
        topic: String,
        index: usize,
        log_time: u64,
        file: PathBuf,
        record_offset: u64,
        source: CdrError,
    },
    /// No topic of that name in the bag.
    #[error("no topic {topic} in the bag")]
    NoSuchTopic { topic: String },
    /// The channel's messages are not CDR, the only encoding of ROS 2 messages rpkm reads.
    #[error("topic {topic}: message encoding {encoding:?}, expected \"cdr\"")]
    Encoding { topic: String, encoding: String },
    /// The bag could not be read while iterating it.
    #[error(transparent)]
    Read(#[from] BagReadError),
}

/// Errors of [`recover`](super::recover).
#[derive(Debug, thiserror::Error)]
pub enum RecoverError {
    /// File system error on the source.
    #[error("I/O error on {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The source has no `.mcap` file.
    #[error("{path} holds no .mcap file to recover")]
    NoMcap { path: PathBuf },
    /// The source does not even start with the MCAP magic and header.
    #[error("{path} is not an MCAP file (bad magic)")]
    BadMagic { path: PathBuf },
    /// Writing the recovered bag failed.
    #[error("writing the recovered bag: {0}")]
    Write(#[from] BagWriteError),
}
