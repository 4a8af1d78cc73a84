//! Reading rosbag2 MCAP folders (or bare `.mcap` files).

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rpkm_msgs::RosMessage;

use super::error::{BagDecodeError, BagOpenError};
use super::metadata::{BagMetadata, METADATA_FILE};
use super::records::{walk_data_section, DataItem, SectionEnd, WalkError};

/// A topic of an open bag.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    pub name: String,
    /// `pkg/msg/Type` (the schema name).
    pub type_name: String,
    /// Message encoding, `cdr` for ROS 2.
    pub message_encoding: String,
    /// Schema encoding, `ros2msg` for ROS 2.
    pub schema_encoding: String,
    /// The schema: `.msg` text with dependencies.
    pub definition: String,
    /// Channel metadata `offered_qos_profiles` (YAML string), empty if absent.
    pub offered_qos_profiles: String,
    /// Channel metadata `topic_type_hash`, if present.
    pub type_hash: Option<String>,
    /// Messages counted in the files (not taken from `metadata.yaml`).
    pub message_count: u64,
}

/// One message of a bag: its payload, and names borrowed from the [`BagReader`].
#[derive(Debug, Clone)]
pub struct BagMessage<'a> {
    pub topic: &'a str,
    /// Index of the topic in [`BagReader::topics`].
    pub topic_index: usize,
    /// `pkg/msg/Type`.
    pub type_name: &'a str,
    /// The channel's message encoding: `cdr` is the only one decoded.
    pub message_encoding: &'a str,
    /// Log (receive) time, ns.
    pub log_time: u64,
    /// Publish time, ns.
    pub publish_time: u64,
    /// Sequence number written with the message.
    pub sequence: u32,
    /// The CDR payload with its encapsulation header.
    pub data: Vec<u8>,
    /// Position in the bag's log-time order.
    pub index: usize,
    /// File holding the message.
    pub file: &'a Path,
    /// Byte offset of the chunk (or message record) holding it in `file`.
    pub record_offset: u64,
}

impl BagMessage<'_> {
    /// Decodes the payload as `T`, after checking that the message's type is `T`'s.
    pub fn decode<T: RosMessage>(&self) -> Result<T, BagDecodeError> {
        let expected = T::type_name();
        // a payload in another encoding (json, protobuf...) would decode as garbage CDR
        if self.message_encoding != "cdr" {
            return Err(BagDecodeError::Encoding {
                topic: self.topic.to_owned(),
                encoding: self.message_encoding.to_owned(),
            });
        }
        if self.type_name != expected {
            return Err(BagDecodeError::TypeMismatch {
                topic: self.topic.to_owned(),
                index: self.index,
                expected,
                found: self.type_name.to_owned(),
            });
        }
        super::cdr::decode_cdr(&self.data).map_err(|source| BagDecodeError::Cdr {
            topic: self.topic.to_owned(),
            index: self.index,
            log_time: self.log_time,
            file: self.file.to_path_buf(),
            record_offset: self.record_offset,
            source,
        })
    }
}

/// A run of messages read back together when its turn comes: a chunk, or a message record
/// outside any chunk.
#[derive(Debug, Clone, Copy)]
pub(super) struct Segment {
    /// Index into the bag's files.
    pub file: usize,
    /// Byte offset of the top-level record in the file.
    pub offset: u64,
    /// Smallest log time of its messages: the segment is read before anything later goes out.
    pub first_log_time: u64,
    pub messages: u64,
}

/// Where a bag's messages are: what the merge needs, shared with its reading thread.
#[derive(Debug, Default)]
pub(super) struct ChunkIndex {
    /// The storage files, in order.
    pub files: Vec<PathBuf>,
    /// Per file: channel id -> index into the topics.
    pub channels: Vec<HashMap<u16, usize>>,
    /// In file order.
    pub segments: Vec<Segment>,
    /// Indices into `segments` by first log time, ties in file order: the order of reading.
    pub schedule: Vec<usize>,
}

/// An open bag: its topics, counts and an index of its chunks.
///
/// `open` reads every file once, linearly, and checks all of it (chunk CRCs, every record, the
/// data section's CRC), keeping for each chunk only where it is and its first log time.
/// [`messages`](Self::messages) reads the chunks again, each when its turn in log-time order
/// comes, so memory stays a few chunks (more only where chunks overlap in time). Files written
/// by any MCAP writer are accepted (chunked or not, compressed with zstd or lz4 or not); a file
/// whose writer did not finish is refused with [`BagOpenError::Truncated`] (see
/// [`recover`](super::recover)).
pub struct BagReader {
    path: PathBuf,
    metadata: Option<BagMetadata>,
    topics: Vec<TopicInfo>,
    index: Arc<ChunkIndex>,
    message_count: usize,
    time_bounds: Option<(u64, u64)>,
}

/// What `open` gathers while it walks the files.
#[derive(Default)]
struct Survey {
    topics: Vec<TopicInfo>,
    index: ChunkIndex,
    message_count: usize,
    time_bounds: Option<(u64, u64)>,
}

impl BagReader {
    /// Opens a rosbag2 folder (with `metadata.yaml`, or else every `.mcap` in it, by name) or a
    /// bare `.mcap` file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, BagOpenError> {
        let path = path.as_ref().to_path_buf();
        let (files, metadata) = storage_files(&path)?;
        let mut survey = Survey::default();
        for (file_index, file) in files.iter().enumerate() {
            survey.walk_file(file, file_index)?;
        }
        let mut index = survey.index;
        index.files = files;
        let mut schedule: Vec<usize> = (0..index.segments.len()).collect();
        // Stable: equal first log times keep their file order.
        schedule.sort_by_key(|&i| index.segments[i].first_log_time);
        index.schedule = schedule;
        Ok(Self {
            path,
            metadata,
            topics: survey.topics,
            index: Arc::new(index),
            message_count: survey.message_count,
            time_bounds: survey.time_bounds,
        })
    }
    /// What was opened.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The storage files read, in order.
    pub fn files(&self) -> &[PathBuf] {
        &self.index.files
    }

    /// `metadata.yaml`, when the bag is a folder that has one.
    pub fn metadata(&self) -> Option<&BagMetadata> {
        self.metadata.as_ref()
    }

    /// Topics in the order they first appear in the files.
    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    /// The topic called `name` (the first one, if several types share the name).
    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// Number of messages.
    pub fn message_count(&self) -> usize {
        self.message_count
    }

    /// First and last log time, ns; `None` for an empty bag.
    pub fn time_bounds(&self) -> Option<(u64, u64)> {
        self.time_bounds
    }

    pub(super) fn index(&self) -> &Arc<ChunkIndex> {
        &self.index
    }
}

impl Survey {
    /// Walks one file: checks it and records its topics, channels and segments.
    fn walk_file(&mut self, file: &Path, file_index: usize) -> Result<(), BagOpenError> {
        let io_err = |source| BagOpenError::Io {
            path: file.to_path_buf(),
            source,
        };
        let handle = File::open(file).map_err(io_err)?;
        let file_len = handle.metadata().map_err(io_err)?.len();
        // schema id -> (name, encoding, text)
        let mut schemas: HashMap<u16, (String, String, String)> = HashMap::new();
        let mut channels: HashMap<u16, usize> = HashMap::new();
        let walked = walk_data_section(
            BufReader::with_capacity(1 << 20, handle),
            file_len,
            |item| -> Result<(), BagOpenError> {
                match item {
                    DataItem::Schema {
                        id,
                        name,
                        encoding,
                        data,
                    } => {
                        let text = String::from_utf8_lossy(data).into_owned();
                        schemas.insert(id, (name.to_owned(), encoding.to_owned(), text));
                    }
                    DataItem::Channel {
                        record_offset,
                        channel,
                    } => {
                        let topic = self.topic_of(channel, &schemas);
                        if channels
                            .insert(channel.id, topic)
                            .is_some_and(|t| t != topic)
                        {
                            return Err(BagOpenError::ChannelRedefined {
                                path: file.to_path_buf(),
                                offset: record_offset,
                                channel_id: channel.id,
                                topic: channel.topic.clone(),
                            });
                        }
                    }
                    DataItem::Message {
                        record_offset,
                        header,
                        ..
                    } => {
                        let Some(&topic) = channels.get(&header.channel_id) else {
                            return Err(BagOpenError::UnknownChannel {
                                path: file.to_path_buf(),
                                offset: record_offset,
                                channel_id: header.channel_id,
                            });
                        };
                        self.count_message(topic, file_index, record_offset, header.log_time);
                    }
                }
                Ok(())
            },
        );
        self.index.channels.push(channels);
        let summary = match walked {
            Ok(summary) => summary,
            Err(WalkError::BadMagic) => {
                return Err(BagOpenError::BadMagic {
                    path: file.to_path_buf(),
                })
            }
            Err(WalkError::Io(source)) => return Err(io_err(source)),
            Err(WalkError::Visit(err)) => return Err(err),
        };
        match summary.end {
            SectionEnd::DataEnd => Ok(()),
            SectionEnd::Eof | SectionEnd::Truncated { .. } => Err(BagOpenError::Truncated {
                path: file.to_path_buf(),
                offset: summary.valid_bytes,
            }),
            SectionEnd::Corrupt { offset, source } => Err(BagOpenError::Corrupt {
                path: file.to_path_buf(),
                offset,
                source,
            }),
        }
    }

    /// The index into `topics` of a channel's topic, added if new. A topic is its name, type
    /// and message encoding: a channel in another encoding is another topic, refused on its
    /// own when decoded or replayed.
    fn topic_of(
        &mut self,
        channel: &mcap::records::Channel,
        schemas: &HashMap<u16, (String, String, String)>,
    ) -> usize {
        let (type_name, schema_encoding, definition) =
            schemas.get(&channel.schema_id).cloned().unwrap_or_default();
        if let Some(index) = self.topics.iter().position(|t| {
            t.name == channel.topic
                && t.type_name == type_name
                && t.message_encoding == channel.message_encoding
        }) {
            return index;
        }
        let metadata = |key| channel.metadata.get(key).cloned();
        self.topics.push(TopicInfo {
            name: channel.topic.clone(),
            type_name,
            message_encoding: channel.message_encoding.clone(),
            schema_encoding,
            definition,
            offered_qos_profiles: metadata(super::format::QOS_METADATA_KEY).unwrap_or_default(),
            type_hash: metadata(super::format::TYPE_HASH_METADATA_KEY),
            message_count: 0,
        });
        self.topics.len() - 1
    }

    /// Counts a message of `topic` in the record at `record_offset` of file `file`.
    fn count_message(&mut self, topic: usize, file: usize, record_offset: u64, log_time: u64) {
        if let Some(info) = self.topics.get_mut(topic) {
            info.message_count += 1;
        }
        self.message_count += 1;
        self.time_bounds = Some(match self.time_bounds {
            Some((first, last)) => (first.min(log_time), last.max(log_time)),
            None => (log_time, log_time),
        });
        match self.index.segments.last_mut() {
            Some(segment) if segment.file == file && segment.offset == record_offset => {
                segment.messages += 1;
                segment.first_log_time = segment.first_log_time.min(log_time);
            }
            _ => self.index.segments.push(Segment {
                file,
                offset: record_offset,
                first_log_time: log_time,
                messages: 1,
            }),
        }
    }
}

/// The storage files of a bag folder or bare file, and its metadata if any.
fn storage_files(path: &Path) -> Result<(Vec<PathBuf>, Option<BagMetadata>), BagOpenError> {
    let io_err = |source| BagOpenError::Io {
        path: path.to_path_buf(),
        source,
    };
    let meta = std::fs::metadata(path).map_err(io_err)?;
    if meta.is_file() {
        return Ok((vec![path.to_path_buf()], None));
    }
    if path.join(METADATA_FILE).is_file() {
        let metadata = BagMetadata::read_from(path)?;
        if metadata.storage_identifier != super::format::STORAGE_IDENTIFIER {
            return Err(BagOpenError::UnsupportedStorage {
                path: path.to_path_buf(),
                storage: metadata.storage_identifier,
            });
        }
        let mut files = Vec::new();
        for relative in &metadata.relative_file_paths {
            // Older rosbag2 versions wrote `<bag>/<file>`: only the file name counts.
            let name = Path::new(relative).file_name().unwrap_or_default();
            let file = path.join(name);
            if !file.is_file() {
                return Err(BagOpenError::MissingFile {
                    path: path.to_path_buf(),
                    file: relative.clone(),
                });
            }
            files.push(file);
        }
        return Ok((files, Some(metadata)));
    }
    let files = mcap_files_in(path).map_err(io_err)?;
    if files.is_empty() {
        return Err(BagOpenError::NotABag {
            path: path.to_path_buf(),
        });
    }
    Ok((files, None))
}

/// The `.mcap` files directly in `dir`, sorted by name.
pub(crate) fn mcap_files_in(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let file = entry?.path();
        if file.is_file() && file.extension().is_some_and(|e| e == "mcap") {
            files.push(file);
        }
    }
    files.sort();
    Ok(files)
}
