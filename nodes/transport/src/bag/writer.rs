//! Writing rosbag2 folders with one MCAP file.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use mcap::records::MessageHeader;
use rpkm_msgs::RosMessage;

use super::error::BagWriteError;
use super::metadata::{BagMetadata, TopicCount};
use super::qos::QosProfile;

/// Chunk compression inside the MCAP file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BagCompression {
    /// No compression: cheapest to write, and what a recorder at kHz rates wants.
    #[default]
    None,
    /// zstd (readable by rosbag2, rosbags, `mcap` Python and Foxglove).
    Zstd,
    /// LZ4 frames.
    Lz4,
}

/// Options of [`BagWriter`].
#[derive(Debug, Clone)]
pub struct BagWriterOptions {
    pub compression: BagCompression,
    /// Uncompressed bytes of messages after which a chunk is closed, written and flushed to the
    /// operating system. A killed writer loses at most this much. Default 1 MiB.
    pub chunk_size: u64,
    /// Also `fsync` the file after each chunk (survives power loss, not only a killed process).
    pub sync_each_chunk: bool,
}

impl Default for BagWriterOptions {
    fn default() -> Self {
        Self {
            compression: BagCompression::None,
            chunk_size: 1024 * 1024,
            sync_each_chunk: false,
        }
    }
}

/// A topic described by strings, for the raw write path.
#[derive(Debug, Clone)]
pub struct RawTopic {
    /// Topic name, e.g. `/actuators/state`.
    pub name: String,
    /// `pkg/msg/Type`.
    pub type_name: String,
    /// `.msg` text with dependencies (schema data, encoding `ros2msg`).
    pub definition: String,
    /// YAML string of the offered QoS profiles (see [`QosProfile::to_rosbag2_yaml`]).
    pub offered_qos_yaml: String,
    /// `RIHS01_...` type hash, when known.
    pub type_hash: Option<String>,
}

/// Handle of a topic added with [`BagWriter::add_topic`]; only writes `T`.
#[derive(Debug)]
pub struct TopicHandle<T> {
    raw: RawTopicHandle,
    _type: PhantomData<fn(&T)>,
}

impl<T> Clone for TopicHandle<T> {
    fn clone(&self) -> Self {
        Self {
            raw: self.raw,
            _type: PhantomData,
        }
    }
}

impl<T> TopicHandle<T> {
    /// The untyped handle, for [`BagWriter::write_raw`].
    pub fn raw(&self) -> RawTopicHandle {
        self.raw
    }
}

/// Handle of a topic for raw (already serialised) writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawTopicHandle {
    writer_id: u64,
    index: usize,
}

/// Summary of a closed bag.
#[derive(Debug, Clone, PartialEq)]
pub struct BagSummary {
    /// The bag folder.
    pub dir: PathBuf,
    /// The MCAP file inside it.
    pub mcap_path: PathBuf,
    /// Messages per topic, in the order the topics were added.
    pub topics: Vec<(String, u64)>,
    pub message_count: u64,
    /// First and last log time, ns; `None` for an empty bag.
    pub time_bounds: Option<(u64, u64)>,
    /// Chunks written.
    pub chunk_count: u64,
}

struct Topic {
    raw: RawTopic,
    channel_id: u16,
    next_sequence: u32,
    count: u64,
}

struct Inner {
    mcap: mcap::Writer<BufWriter<File>>,
    topics: Vec<Topic>,
    /// Approximate uncompressed bytes of the open chunk (message records only).
    open_chunk_bytes: u64,
    chunk_count: u64,
    /// Messages written so far, and those of them in closed (written and flushed) chunks.
    message_count: u64,
    flushed_message_count: u64,
    time_bounds: Option<(u64, u64)>,
    /// Reused serialisation buffer.
    scratch: Vec<u8>,
}

/// Writes a rosbag2 folder `<dir>` holding `<name>_0.mcap` and, at [`finish`](Self::finish),
/// `metadata.yaml`, where `<name>` is the folder's final name.
///
/// ```no_run
/// # use rpkm_transport::bag::{BagWriter, BagWriterOptions, QosProfile};
/// # fn demo<M: rpkm_msgs::RosMessage>(msg: M) -> Result<(), rpkm_transport::bag::BagWriteError> {
/// let mut bag = BagWriter::create("bags/run1", BagWriterOptions::default())?;
/// let state = bag.add_topic::<M>("/actuators/state", &QosProfile::sensor_data())?;
/// bag.write(&state, 1_700_000_000_000_000_000, &msg)?;
/// bag.finish()?;
/// # Ok(()) }
/// ```
pub struct BagWriter {
    id: u64,
    dir: PathBuf,
    mcap_path: PathBuf,
    options: BagWriterOptions,
    inner: Option<Inner>,
}

/// Distinguishes writers so that a handle cannot write into another bag.
static NEXT_WRITER_ID: AtomicU64 = AtomicU64::new(1);

/// Any call after [`BagWriter::finish`] (only reachable from `Drop`).
const FINISHED: BagWriteError = BagWriteError::Limit {
    what: "bag writer already finished",
};

/// Bytes of a message record besides its payload: opcode, length, channel id, sequence, times.
const MESSAGE_RECORD_OVERHEAD: u64 = 1 + 8 + 2 + 4 + 8 + 8;

impl BagWriter {
    /// Creates the folder `dir` (which must not exist; missing parents are created) and the
    /// MCAP file.
    pub fn create(dir: impl AsRef<Path>, options: BagWriterOptions) -> Result<Self, BagWriteError> {
        let dir = dir.as_ref().to_path_buf();
        let name = dir
            .file_name()
            .and_then(|n| n.to_str())
            .filter(|n| !n.is_empty() && *n != "." && *n != "..")
            .ok_or_else(|| BagWriteError::BadName { path: dir.clone() })?
            .to_owned();
        if dir.exists() {
            return Err(BagWriteError::AlreadyExists { path: dir });
        }
        if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|source| BagWriteError::Io {
                path: parent.to_path_buf(),
                source,
            })?;
        }
        std::fs::create_dir(&dir).map_err(|source| BagWriteError::Io {
            path: dir.clone(),
            source,
        })?;
        let mcap_path = dir.join(format!("{name}_0.mcap"));
        let file = File::create_new(&mcap_path).map_err(|source| BagWriteError::Io {
            path: mcap_path.clone(),
            source,
        })?;
        let compression = match options.compression {
            BagCompression::None => None,
            BagCompression::Zstd => Some(mcap::Compression::Zstd),
            BagCompression::Lz4 => Some(mcap::Compression::Lz4),
        };
        // Chunks are closed by this writer (see `after_message`), never by mcap itself, and are
        // buffered in memory until closed (`disable_seeking`): the file never holds a
        // half-written chunk, only complete ones followed by their message indexes.
        let write_options = mcap::WriteOptions::new()
            .profile(super::format::PROFILE)
            .library(concat!("rpkm-transport/", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .chunk_size(None)
            .use_chunks(true)
            .disable_seeking(true)
            .compression_threads(0);
        let mcap = write_options
            .create(BufWriter::with_capacity(256 * 1024, file))
            .map_err(|source| BagWriteError::Mcap {
                path: mcap_path.clone(),
                source,
            })?;
        let mut writer = Self {
            id: NEXT_WRITER_ID.fetch_add(1, Ordering::Relaxed),
            dir,
            mcap_path,
            options,
            inner: Some(Inner {
                mcap,
                topics: Vec::new(),
                open_chunk_bytes: 0,
                chunk_count: 0,
                message_count: 0,
                flushed_message_count: 0,
                time_bounds: None,
                scratch: Vec::new(),
            }),
        };
        // Put the header on disk at once: even a writer killed before its first chunk leaves a
        // file that recovery recognises.
        writer.flush_file()?;
        Ok(writer)
    }

    /// The bag folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The MCAP file inside the folder.
    pub fn mcap_path(&self) -> &Path {
        &self.mcap_path
    }

    /// Adds a topic of type `T` (or returns the existing handle if it was added with `T`).
    pub fn add_topic<T: RosMessage>(
        &mut self,
        topic: &str,
        qos: &QosProfile,
    ) -> Result<TopicHandle<T>, BagWriteError> {
        let raw = self.add_topic_raw(RawTopic {
            name: topic.to_owned(),
            type_name: T::type_name(),
            definition: T::definition(),
            offered_qos_yaml: qos.to_rosbag2_yaml(),
            type_hash: None,
        })?;
        Ok(TopicHandle {
            raw,
            _type: PhantomData,
        })
    }

    /// Adds a topic described by strings (the recorder's path).
    pub fn add_topic_raw(&mut self, topic: RawTopic) -> Result<RawTopicHandle, BagWriteError> {
        let writer_id = self.id;
        let path = self.mcap_path.clone();
        let inner = self.inner_mut()?;
        if let Some(index) = inner.topics.iter().position(|t| t.raw.name == topic.name) {
            let existing = &inner.topics[index].raw;
            if existing.type_name != topic.type_name {
                return Err(BagWriteError::TopicTypeConflict {
                    topic: topic.name,
                    existing: existing.type_name.clone(),
                    requested: topic.type_name,
                });
            }
            return Ok(RawTopicHandle { writer_id, index });
        }
        let mcap_err = |source| BagWriteError::Mcap {
            path: path.clone(),
            source,
        };
        let schema_id = inner
            .mcap
            .add_schema(
                &topic.type_name,
                super::format::SCHEMA_ENCODING,
                topic.definition.as_bytes(),
            )
            .map_err(mcap_err)?;
        let mut metadata = BTreeMap::new();
        metadata.insert(
            super::format::QOS_METADATA_KEY.to_owned(),
            topic.offered_qos_yaml.clone(),
        );
        if let Some(hash) = &topic.type_hash {
            metadata.insert(
                super::format::TYPE_HASH_METADATA_KEY.to_owned(),
                hash.clone(),
            );
        }
        let channel_id = inner
            .mcap
            .add_channel(
                schema_id,
                &topic.name,
                super::format::MESSAGE_ENCODING,
                &metadata,
            )
            .map_err(mcap_err)?;
        inner.topics.push(Topic {
            raw: topic,
            channel_id,
            next_sequence: 0,
            count: 0,
        });
        Ok(RawTopicHandle {
            writer_id,
            index: inner.topics.len() - 1,
        })
    }

    /// Serialises `message` (CDR) and writes it with log and publish time `stamp_ns`.
    pub fn write<T: RosMessage>(
        &mut self,
        topic: &TopicHandle<T>,
        stamp_ns: u64,
        message: &T,
    ) -> Result<(), BagWriteError> {
        let index = self.check_handle(topic.raw)?;
        let inner = self.inner_mut()?;
        let mut scratch = std::mem::take(&mut inner.scratch);
        let encoded = super::cdr::encode_cdr(message, &mut scratch).map_err(|source| {
            BagWriteError::Serialize {
                topic: inner.topics[index].raw.name.clone(),
                type_name: T::type_name(),
                source,
            }
        });
        let result = encoded.and_then(|()| self.write_raw(topic.raw, stamp_ns, stamp_ns, &scratch));
        if let Some(inner) = self.inner.as_mut() {
            inner.scratch = scratch;
        }
        result
    }

    /// Writes an already serialised CDR payload (with its 4-byte encapsulation header).
    /// The sequence number is the topic's count of messages so far.
    pub fn write_raw(
        &mut self,
        topic: RawTopicHandle,
        log_time_ns: u64,
        publish_time_ns: u64,
        cdr: &[u8],
    ) -> Result<(), BagWriteError> {
        let index = self.check_handle(topic)?;
        let inner = self.inner_mut()?;
        let sequence = inner.topics[index].next_sequence;
        self.write_record(index, sequence, log_time_ns, publish_time_ns, cdr)
    }

    /// Like [`write_raw`](Self::write_raw) with an explicit sequence number (recovery keeps the
    /// original ones).
    pub(crate) fn write_raw_with_sequence(
        &mut self,
        topic: RawTopicHandle,
        sequence: u32,
        log_time_ns: u64,
        publish_time_ns: u64,
        cdr: &[u8],
    ) -> Result<(), BagWriteError> {
        let index = self.check_handle(topic)?;
        self.write_record(index, sequence, log_time_ns, publish_time_ns, cdr)
    }

    fn write_record(
        &mut self,
        index: usize,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: &[u8],
    ) -> Result<(), BagWriteError> {
        let Some(inner) = self.inner.as_mut() else {
            return Err(FINISHED);
        };
        let topic = &mut inner.topics[index];
        let header = MessageHeader {
            channel_id: topic.channel_id,
            sequence,
            log_time,
            publish_time,
        };
        topic.next_sequence = sequence.wrapping_add(1);
        topic.count += 1;
        inner.message_count += 1;
        inner.time_bounds = Some(match inner.time_bounds {
            None => (log_time, log_time),
            Some((lo, hi)) => (lo.min(log_time), hi.max(log_time)),
        });
        let result = inner.mcap.write_to_known_channel(&header, data);
        result.map_err(|source| BagWriteError::Mcap {
            path: self.mcap_path.clone(),
            source,
        })?;
        inner.open_chunk_bytes += MESSAGE_RECORD_OVERHEAD + data.len() as u64;
        if inner.open_chunk_bytes >= self.options.chunk_size {
            self.close_chunk()?;
        }
        Ok(())
    }

    /// Closes the open chunk (if any), writes it and hands the file's buffer to the operating
    /// system. Called automatically when a chunk is full; call it to bound the loss in time
    /// too (e.g. once a second on slow topics).
    pub fn flush(&mut self) -> Result<(), BagWriteError> {
        self.close_chunk()
    }

    fn close_chunk(&mut self) -> Result<(), BagWriteError> {
        let inner = self.inner_mut()?;
        let closing = inner.open_chunk_bytes > 0;
        let messages = inner.message_count;
        self.flush_file()?;
        if let Some(inner) = self.inner.as_mut() {
            if closing {
                inner.chunk_count += 1;
                inner.open_chunk_bytes = 0;
            }
            inner.flushed_message_count = messages;
        }
        Ok(())
    }

    /// Messages written so far (including the open chunk's).
    pub fn message_count(&self) -> u64 {
        self.inner.as_ref().map_or(0, |i| i.message_count)
    }

    /// Messages in chunks already handed to the operating system: what survives if this
    /// process is killed now.
    pub fn flushed_message_count(&self) -> u64 {
        self.inner.as_ref().map_or(0, |i| i.flushed_message_count)
    }

    /// `mcap::Writer::flush` closes the open chunk and flushes the `BufWriter` into the file.
    fn flush_file(&mut self) -> Result<(), BagWriteError> {
        let path = self.mcap_path.clone();
        let sync = self.options.sync_each_chunk;
        let inner = self.inner_mut()?;
        inner.mcap.flush().map_err(|source| BagWriteError::Mcap {
            path: path.clone(),
            source,
        })?;
        if sync {
            // Reach the file through a second handle: the writer's is behind the BufWriter.
            File::open(&path)
                .and_then(|f| f.sync_data())
                .map_err(|source| BagWriteError::Io { path, source })?;
        }
        Ok(())
    }

    /// Closes the last chunk, writes the MCAP summary and footer, syncs the file and writes
    /// `metadata.yaml`.
    pub fn finish(mut self) -> Result<BagSummary, BagWriteError> {
        self.finish_inner()
    }

    fn finish_inner(&mut self) -> Result<BagSummary, BagWriteError> {
        self.close_chunk()?;
        let Some(mut inner) = self.inner.take() else {
            return Err(BagWriteError::Limit {
                what: "bag writer already finished",
            });
        };
        let path = self.mcap_path.clone();
        inner.mcap.finish().map_err(|source| BagWriteError::Mcap {
            path: path.clone(),
            source,
        })?;
        let mut file = inner.mcap.into_inner();
        file.flush().map_err(|source| BagWriteError::Io {
            path: path.clone(),
            source,
        })?;
        file.get_ref()
            .sync_all()
            .map_err(|source| BagWriteError::Io {
                path: path.clone(),
                source,
            })?;
        let file_name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_owned();
        let counts: Vec<TopicCount<'_>> = inner
            .topics
            .iter()
            .map(|t| TopicCount {
                name: &t.raw.name,
                type_name: &t.raw.type_name,
                qos_yaml: &t.raw.offered_qos_yaml,
                type_hash: t.raw.type_hash.as_deref(),
                count: t.count,
            })
            .collect();
        BagMetadata::for_single_file(&file_name, &counts, inner.time_bounds).write_to(&self.dir)?;
        Ok(BagSummary {
            dir: self.dir.clone(),
            mcap_path: path,
            topics: inner
                .topics
                .iter()
                .map(|t| (t.raw.name.clone(), t.count))
                .collect(),
            message_count: inner.topics.iter().map(|t| t.count).sum(),
            time_bounds: inner.time_bounds,
            chunk_count: inner.chunk_count,
        })
    }

    fn check_handle(&self, handle: RawTopicHandle) -> Result<usize, BagWriteError> {
        let known = self
            .inner
            .as_ref()
            .is_some_and(|inner| handle.index < inner.topics.len());
        if handle.writer_id != self.id || !known {
            return Err(BagWriteError::ForeignHandle {
                index: handle.index,
            });
        }
        Ok(handle.index)
    }

    fn inner_mut(&mut self) -> Result<&mut Inner, BagWriteError> {
        self.inner.as_mut().ok_or(FINISHED)
    }
}

impl Drop for BagWriter {
    /// Finishes the bag if [`finish`](BagWriter::finish) was not called. Errors cannot be
    /// reported here; call `finish` to see them.
    fn drop(&mut self) {
        if self.inner.is_some() {
            let _ = self.finish_inner();
        }
    }
}
