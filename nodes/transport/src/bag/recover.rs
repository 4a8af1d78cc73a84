//! Recovery of a bag whose writer was killed: copy what is complete into a new bag.

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use super::error::{BagWriteError, RecoverError};
use super::reader::mcap_files_in;
use super::records::{walk_data_section, DataItem, SectionEnd, WalkError};
use super::writer::{BagWriter, BagWriterOptions, RawTopic, RawTopicHandle};

/// Why reading a source file stopped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StopReason {
    /// The data section was complete (`DataEnd` record): nothing was lost.
    Complete,
    /// The file ends at a record boundary (killed between chunks).
    EndOfFile,
    /// The file ends inside the record starting at `offset`, `missing` bytes short.
    TruncatedRecord { offset: u64, missing: u64 },
    /// The record at `offset` is complete but unreadable (bad CRC, bad length, ...).
    CorruptRecord { offset: u64, error: String },
}

/// What [`recover`] did with one source file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileRecovery {
    pub path: PathBuf,
    pub file_bytes: u64,
    /// Bytes up to the end of the last complete, valid record.
    pub valid_bytes: u64,
    /// `file_bytes - valid_bytes`: the incomplete (or unreadable) tail.
    pub lost_bytes: u64,
    pub chunks: u64,
    pub messages: u64,
    pub stop: StopReason,
}

/// What [`recover`] produced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecoveryReport {
    /// The new bag folder.
    pub destination: PathBuf,
    /// Per source file, in order.
    pub files: Vec<FileRecovery>,
    /// Messages copied, over all files.
    pub messages_recovered: u64,
    /// Bytes of the sources that were complete records.
    pub bytes_recovered: u64,
    /// Bytes of the sources' incomplete or unreadable tails.
    pub bytes_lost: u64,
    /// Messages per topic in the new bag.
    pub topics: Vec<(String, u64)>,
}

/// Copies every complete chunk (and top-level message) of `src` — a bag folder, possibly
/// without `metadata.yaml`, or a bare `.mcap` — into a new bag folder `dst`, with its schemas,
/// channels, times and sequence numbers, and writes a fresh `metadata.yaml`.
///
/// The source is read linearly: its summary, footer and end magic are not needed, and reading
/// stops at the first record that is cut short or cannot be parsed. A chunk is copied whole or
/// not at all.
pub fn recover(
    src: impl AsRef<Path>,
    dst: impl AsRef<Path>,
) -> Result<RecoveryReport, RecoverError> {
    let src = src.as_ref();
    let io_err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| RecoverError::Io { path, source }
    };
    let sources = if std::fs::metadata(src).map_err(io_err(src))?.is_file() {
        vec![src.to_path_buf()]
    } else {
        mcap_files_in(src).map_err(io_err(src))?
    };
    if sources.is_empty() {
        return Err(RecoverError::NoMcap {
            path: src.to_path_buf(),
        });
    }
    let mut writer = BagWriter::create(dst, BagWriterOptions::default())?;
    let mut files = Vec::new();
    for source in &sources {
        files.push(recover_file(source, &mut writer)?);
    }
    let summary = writer.finish()?;
    Ok(RecoveryReport {
        destination: summary.dir,
        messages_recovered: summary.message_count,
        bytes_recovered: files.iter().map(|f| f.valid_bytes).sum(),
        bytes_lost: files.iter().map(|f| f.lost_bytes).sum(),
        files,
        topics: summary.topics,
    })
}

/// Why the walk over a file's data section stopped, as the recovery reports it.
fn stop_reason(end: SectionEnd) -> StopReason {
    match end {
        SectionEnd::DataEnd => StopReason::Complete,
        SectionEnd::Eof => StopReason::EndOfFile,
        SectionEnd::Truncated { offset, missing } => {
            StopReason::TruncatedRecord { offset, missing }
        }
        SectionEnd::Corrupt { offset, source } => StopReason::CorruptRecord {
            offset,
            error: source.to_string(),
        },
    }
}

fn recover_file(path: &Path, writer: &mut BagWriter) -> Result<FileRecovery, RecoverError> {
    let io_err = |source| RecoverError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = File::open(path).map_err(io_err)?;
    let file_bytes = file.metadata().map_err(io_err)?.len();
    let mut schemas: HashMap<u16, (String, String)> = HashMap::new();
    let mut channels: HashMap<u16, RawTopicHandle> = HashMap::new();
    let walked = walk_data_section(
        BufReader::with_capacity(1 << 20, file),
        file_bytes,
        |item| -> Result<(), BagWriteError> {
            match item {
                DataItem::Schema { id, name, data, .. } => {
                    let text = String::from_utf8_lossy(data).into_owned();
                    schemas.insert(id, (name.to_owned(), text));
                }
                DataItem::Channel { channel, .. } => {
                    let (type_name, definition) =
                        schemas.get(&channel.schema_id).cloned().unwrap_or_default();
                    let handle = writer.add_topic_raw(RawTopic {
                        name: channel.topic.clone(),
                        type_name,
                        definition,
                        offered_qos_yaml: channel
                            .metadata
                            .get(super::format::QOS_METADATA_KEY)
                            .cloned()
                            .unwrap_or_default(),
                        type_hash: channel
                            .metadata
                            .get(super::format::TYPE_HASH_METADATA_KEY)
                            .cloned(),
                    })?;
                    channels.insert(channel.id, handle);
                }
                DataItem::Message { header, data, .. } => {
                    // A message of a channel never defined cannot be described: skip it.
                    if let Some(&handle) = channels.get(&header.channel_id) {
                        writer.write_raw_with_sequence(
                            handle,
                            header.sequence,
                            header.log_time,
                            header.publish_time,
                            data,
                        )?;
                    }
                }
            }
            Ok(())
        },
    );
    let summary = match walked {
        Ok(summary) => summary,
        Err(WalkError::BadMagic) => {
            return Err(RecoverError::BadMagic {
                path: path.to_path_buf(),
            })
        }
        Err(WalkError::Io(source)) => return Err(io_err(source)),
        Err(WalkError::Visit(err)) => return Err(err.into()),
    };
    let stop = stop_reason(summary.end);
    // A complete file's summary section is not lost, only not needed.
    let lost_bytes = match stop {
        StopReason::Complete => 0,
        _ => file_bytes.saturating_sub(summary.valid_bytes),
    };
    Ok(FileRecovery {
        path: path.to_path_buf(),
        file_bytes,
        valid_bytes: summary.valid_bytes,
        lost_bytes,
        chunks: summary.chunks,
        messages: summary.messages,
        stop,
    })
}
