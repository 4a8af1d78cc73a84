//! Reading rosbag2 MCAP folders (or bare `.mcap` files).

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

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

/// One message of a bag, borrowed from the [`BagReader`].
#[derive(Debug, Clone, Copy)]
pub struct BagMessage<'a> {
    pub topic: &'a str,
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
    pub data: &'a [u8],
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
        super::cdr::decode_cdr(self.data).map_err(|source| BagDecodeError::Cdr {
            topic: self.topic.to_owned(),
            index: self.index,
            log_time: self.log_time,
            file: self.file.to_path_buf(),
            record_offset: self.record_offset,
            source,
        })
    }
}

struct Entry {
    topic: u32,
    file: u16,
    sequence: u32,
    log_time: u64,
    publish_time: u64,
    record_offset: u64,
    start: usize,
    len: usize,
}

/// An open bag: all its messages, in log-time order.
///
/// `open` reads every file once, linearly, and keeps the payloads in one buffer, so iteration
/// and decoding do not touch the disk; memory is about the size of the messages. Files written
/// by any MCAP writer are accepted (chunked or not, compressed with zstd or lz4 or not); a file
/// whose writer did not finish is refused with [`BagOpenError::Truncated`] (see
/// [`recover`](super::recover)).
pub struct BagReader {
    path: PathBuf,
    files: Vec<PathBuf>,
    metadata: Option<BagMetadata>,
    topics: Vec<TopicInfo>,
    entries: Vec<Entry>,
    payloads: Vec<u8>,
}

impl BagReader {
    /// Opens a rosbag2 folder (with `metadata.yaml`, or else every `.mcap` in it, by name) or a
    /// bare `.mcap` file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, BagOpenError> {
        let path = path.as_ref().to_path_buf();
        let (files, metadata) = storage_files(&path)?;
        let mut reader = Self {
            path,
            files: Vec::new(),
            metadata,
            topics: Vec::new(),
            entries: Vec::new(),
            payloads: Vec::new(),
        };
        for (file_index, file) in files.iter().enumerate() {
            let file_index = u16::try_from(file_index).unwrap_or(u16::MAX);
            reader.read_file(file, file_index)?;
        }
        reader.files = files;
        if !reader.entries.is_sorted_by_key(|e| e.log_time) {
            // Stable: equal log times keep their file order.
            reader.entries.sort_by_key(|e| e.log_time);
        }
        Ok(reader)
    }

    fn read_file(&mut self, file: &Path, file_index: u16) -> Result<(), BagOpenError> {
        let io_err = |source| BagOpenError::Io {
            path: file.to_path_buf(),
            source,
        };
        let handle = File::open(file).map_err(io_err)?;
        let file_len = handle.metadata().map_err(io_err)?.len();
        // Per file: schema id -> (name, encoding, text); channel id -> topic index.
        let mut schemas: HashMap<u16, (String, String, String)> = HashMap::new();
        let mut channels: HashMap<u16, u32> = HashMap::new();
        let topics = &mut self.topics;
        let entries = &mut self.entries;
        let payloads = &mut self.payloads;
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
                    DataItem::Channel(channel) => {
                        let (type_name, schema_encoding, definition) =
                            schemas.get(&channel.schema_id).cloned().unwrap_or_default();
                        let index = match topics
                            .iter()
                            .position(|t| t.name == channel.topic && t.type_name == type_name)
                        {
                            Some(index) => index,
                            None => {
                                topics.push(TopicInfo {
                                    name: channel.topic.clone(),
                                    type_name,
                                    message_encoding: channel.message_encoding.clone(),
                                    schema_encoding,
                                    definition,
                                    offered_qos_profiles: channel
                                        .metadata
                                        .get(super::QOS_METADATA_KEY)
                                        .cloned()
                                        .unwrap_or_default(),
                                    type_hash: channel
                                        .metadata
                                        .get(super::TYPE_HASH_METADATA_KEY)
                                        .cloned(),
                                    message_count: 0,
                                });
                                topics.len() - 1
                            }
                        };
                        channels.insert(channel.id, u32::try_from(index).unwrap_or(u32::MAX));
                    }
                    DataItem::Message {
                        record_offset,
                        header,
                        data,
                    } => {
                        let Some(&topic) = channels.get(&header.channel_id) else {
                            return Err(BagOpenError::UnknownChannel {
                                path: file.to_path_buf(),
                                offset: record_offset,
                                channel_id: header.channel_id,
                            });
                        };
                        if let Some(info) = topics.get_mut(topic as usize) {
                            info.message_count += 1;
                        }
                        entries.push(Entry {
                            topic,
                            file: file_index,
                            sequence: header.sequence,
                            log_time: header.log_time,
                            publish_time: header.publish_time,
                            record_offset,
                            start: payloads.len(),
                            len: data.len(),
                        });
                        payloads.extend_from_slice(data);
                    }
                }
                Ok(())
            },
        );
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

    /// What was opened.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The storage files read, in order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
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
        self.entries.len()
    }

    /// First and last log time, ns; `None` for an empty bag.
    pub fn time_bounds(&self) -> Option<(u64, u64)> {
        Some((
            self.entries.first()?.log_time,
            self.entries.last()?.log_time,
        ))
    }

    /// All messages in log-time order (ties in file order).
    pub fn messages(&self) -> impl ExactSizeIterator<Item = BagMessage<'_>> + '_ {
        self.entries
            .iter()
            .enumerate()
            .map(move |(index, entry)| self.message(index, entry))
    }

    /// Decodes every message of `topic` as `T`, with its log time, in log-time order.
    pub fn decode_topic<T: RosMessage>(
        &self,
        topic: &str,
    ) -> Result<Vec<(u64, T)>, BagDecodeError> {
        let Some(wanted) = self.topics.iter().position(|t| t.name == topic) else {
            return Err(BagDecodeError::NoSuchTopic {
                topic: topic.to_owned(),
            });
        };
        self.entries
            .iter()
            .enumerate()
            .filter(|(_, e)| e.topic as usize == wanted)
            .map(|(index, entry)| {
                let message = self.message(index, entry);
                message.decode::<T>().map(|value| (message.log_time, value))
            })
            .collect()
    }

    fn message<'a>(&'a self, index: usize, entry: &Entry) -> BagMessage<'a> {
        let topic = self.topics.get(entry.topic as usize);
        BagMessage {
            topic: topic.map_or("", |t| t.name.as_str()),
            type_name: topic.map_or("", |t| t.type_name.as_str()),
            message_encoding: topic.map_or("", |t| t.message_encoding.as_str()),
            log_time: entry.log_time,
            publish_time: entry.publish_time,
            sequence: entry.sequence,
            data: self
                .payloads
                .get(entry.start..entry.start + entry.len)
                .unwrap_or_default(),
            index,
            file: self
                .files
                .get(entry.file as usize)
                .map_or(Path::new(""), |p| p.as_path()),
            record_offset: entry.record_offset,
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
        if metadata.storage_identifier != super::STORAGE_IDENTIFIER {
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
