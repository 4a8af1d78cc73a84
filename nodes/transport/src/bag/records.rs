//! A linear walk over an MCAP data section that tolerates a missing end.
//!
//! Shared by the reader (which insists on a complete file) and the recovery (which keeps what is
//! complete). Top-level records are framed here (opcode, u64 length, body), so every record's
//! byte offset is known and a record cut short by the end of the file is detected before anything
//! is allocated for it. Chunks are all-or-nothing: their records are visited only after the whole
//! chunk was decompressed, its CRC checked (where the writer stored one) and every record in it
//! parsed. The data section's own CRC, stored in `DataEnd`, is checked over every byte before it.

use std::io::{self, Read};

use mcap::records::{op, Channel, MessageHeader, Record};

/// A schema, channel or message from the data section.
pub(crate) enum DataItem<'a> {
    Schema {
        id: u16,
        name: &'a str,
        encoding: &'a str,
        data: &'a [u8],
    },
    Channel {
        /// Byte offset of the top-level record holding the channel (a chunk or the channel).
        record_offset: u64,
        channel: &'a Channel,
    },
    Message {
        /// Byte offset of the top-level record holding the message (a chunk or the message).
        record_offset: u64,
        header: &'a MessageHeader,
        data: &'a [u8],
    },
}

/// How the data section ended.
#[derive(Debug)]
pub(crate) enum SectionEnd {
    /// A `DataEnd` record: the writer finished the data section.
    DataEnd,
    /// The file ends at a record boundary without `DataEnd`.
    Eof,
    /// The file ends inside the record at `offset`, `missing` bytes short.
    Truncated { offset: u64, missing: u64 },
    /// The record at `offset` is complete but cannot be parsed (or a chunk fails its CRC).
    Corrupt {
        offset: u64,
        source: mcap::McapError,
    },
}

/// Outcome of a walk.
#[derive(Debug)]
pub(crate) struct SectionSummary {
    pub end: SectionEnd,
    /// Offset just after the last complete, valid record.
    pub valid_bytes: u64,
    pub chunks: u64,
    pub messages: u64,
}

/// Errors that stop a walk before its end: bad magic, I/O, or the visitor's own error.
pub(crate) enum WalkError<E> {
    BadMagic,
    Io(io::Error),
    Visit(E),
}

/// Reads as many bytes as are left, up to `buf.len()`; returns how many.
fn read_full(reader: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(err) if err.kind() == io::ErrorKind::Interrupted => {}
            Err(err) => return Err(err),
        }
    }
    Ok(filled)
}

/// Walks the data section of an MCAP stream of `file_len` bytes, calling `visit` for every
/// schema, channel and message in file order, until `DataEnd`, the end of the file, a truncated
/// or a corrupt record.
pub(crate) fn walk_data_section<R: Read, E>(
    mut reader: R,
    file_len: u64,
    mut visit: impl FnMut(DataItem<'_>) -> Result<(), E>,
) -> Result<SectionSummary, WalkError<E>> {
    let mut magic = [0u8; 8];
    let n = read_full(&mut reader, &mut magic).map_err(WalkError::Io)?;
    if n < magic.len() || magic != mcap::MAGIC {
        return Err(WalkError::BadMagic);
    }
    let mut offset = magic.len() as u64;
    let mut body = Vec::new();
    // CRC-32 of everything before DataEnd, magic included (as mcap's writer computes it)
    let mut crc = crc32fast::Hasher::new();
    crc.update(&magic);
    let mut summary = SectionSummary {
        end: SectionEnd::Eof,
        valid_bytes: offset,
        chunks: 0,
        messages: 0,
    };
    loop {
        let mut frame = [0u8; 9];
        let len = match read_record(&mut reader, file_len, offset, &mut frame, &mut body) {
            Ok(Ok(len)) => len,
            Ok(Err(end)) => {
                summary.end = end;
                return Ok(summary);
            }
            Err(e) => return Err(WalkError::Io(e)),
        };
        let opcode = frame[0];
        let record_offset = offset;
        let next_offset = offset + frame.len() as u64 + len;
        match opcode {
            op::DATA_END => {
                summary.end = data_end(&body, crc.finalize(), record_offset);
                if matches!(summary.end, SectionEnd::DataEnd) {
                    summary.valid_bytes = next_offset;
                }
                return Ok(summary);
            }
            op::SCHEMA | op::CHANNEL | op::MESSAGE | op::CHUNK => {
                let record = match mcap::parse_record(opcode, &body) {
                    Ok(record) => record,
                    Err(source) => {
                        summary.end = SectionEnd::Corrupt {
                            offset: record_offset,
                            source,
                        };
                        return Ok(summary);
                    }
                };
                if let Record::Chunk { header, data } = record {
                    let inner = match chunk_records(header, &data) {
                        Ok(inner) => inner,
                        Err(source) => {
                            summary.end = SectionEnd::Corrupt {
                                offset: record_offset,
                                source,
                            };
                            return Ok(summary);
                        }
                    };
                    for record in &inner {
                        summary.messages += visit_record(record, record_offset, &mut visit)?;
                    }
                    summary.chunks += 1;
                } else {
                    summary.messages += visit_record(&record, record_offset, &mut visit)?;
                }
            }
            // Header, message indexes, attachments, metadata, private records: not needed.
            _ => {}
        }
        crc.update(&frame);
        crc.update(&body);
        summary.valid_bytes = next_offset;
        offset = next_offset;
    }
}

/// Reads the record at `offset`: its opcode and length into `frame`, its body into `body`.
/// Returns the body's length, or how the data section ends there (at a record boundary, or
/// inside a record whose length the file does not hold).
fn read_record<R: Read>(
    reader: &mut R,
    file_len: u64,
    offset: u64,
    frame: &mut [u8; 9],
    body: &mut Vec<u8>,
) -> std::io::Result<Result<u64, SectionEnd>> {
    let got = read_full(reader, frame)?;
    if got == 0 {
        return Ok(Err(SectionEnd::Eof));
    }
    if got < frame.len() {
        let missing = (frame.len() - got) as u64;
        return Ok(Err(SectionEnd::Truncated { offset, missing }));
    }
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&frame[1..]);
    let len = u64::from_le_bytes(len_bytes);
    let available = file_len.saturating_sub(offset + frame.len() as u64);
    // Do not trust the length (nor allocate for it) beyond what the file holds; and
    // `len <= available <= file_len` fits in memory only if it fits in usize.
    let len_usize = match usize::try_from(len) {
        Ok(n) if len <= available => n,
        _ => {
            let missing = len.saturating_sub(available);
            return Ok(Err(SectionEnd::Truncated { offset, missing }));
        }
    };
    body.resize(len_usize, 0);
    let got = read_full(reader, body)?;
    if got < len_usize {
        // The file shrank or grew differently than its length said.
        let missing = (len_usize - got) as u64;
        return Ok(Err(SectionEnd::Truncated { offset, missing }));
    }
    Ok(Ok(len))
}

/// The records of a chunk: decompressed, its CRC checked where the writer stored one, every
/// record parsed.
fn chunk_records(
    header: mcap::records::ChunkHeader,
    data: &[u8],
) -> Result<Vec<Record<'static>>, mcap::McapError> {
    // the records are owned already; `into_owned` only restates their lifetime
    mcap::read::ChunkReader::new(header, data)?
        .map(|record| record.map(Record::into_owned))
        .collect()
}

/// Why [`read_segment`] failed.
#[derive(Debug)]
pub(crate) enum SegmentError {
    Io(io::Error),
    /// The record's length runs `missing` bytes past the end of the file.
    PastEnd {
        missing: u64,
    },
    /// The record does not parse, or its chunk fails its CRC.
    Corrupt(mcap::McapError),
}

/// Reads the top-level record that starts at `reader`'s position, with `available` bytes of the
/// file left from there: the records of a chunk (decompressed, CRC-checked), or the record
/// itself. Also returns the bytes consumed. The reader's way back to a chunk whose turn has
/// come in a merge: [`walk_data_section`] has validated the file before.
pub(crate) fn read_segment(
    reader: &mut impl Read,
    available: u64,
) -> Result<(u64, Vec<Record<'static>>), SegmentError> {
    let mut frame = [0u8; 9];
    reader.read_exact(&mut frame).map_err(SegmentError::Io)?;
    let mut len_bytes = [0u8; 8];
    len_bytes.copy_from_slice(&frame[1..]);
    let len = u64::from_le_bytes(len_bytes);
    let room = available.saturating_sub(frame.len() as u64);
    // Never allocate for a length the file cannot hold.
    let len_usize = match usize::try_from(len) {
        Ok(n) if len <= room => n,
        _ => {
            return Err(SegmentError::PastEnd {
                missing: len - room,
            })
        }
    };
    let mut body = vec![0u8; len_usize];
    reader.read_exact(&mut body).map_err(SegmentError::Io)?;
    let record = mcap::parse_record(frame[0], &body).map_err(SegmentError::Corrupt)?;
    let records = match record {
        Record::Chunk { header, data } => {
            chunk_records(header, &data).map_err(SegmentError::Corrupt)?
        }
        other => vec![other.into_owned()],
    };
    Ok((frame.len() as u64 + len, records))
}

/// The end of a data section at a `DataEnd` record of body `body` at `offset`: complete when
/// its stored CRC (0: none stored) equals `computed`, the CRC of every byte before it.
fn data_end(body: &[u8], computed: u32, offset: u64) -> SectionEnd {
    let saved = match mcap::parse_record(op::DATA_END, body) {
        Ok(Record::DataEnd(end)) => end.data_section_crc,
        Ok(_) => return SectionEnd::DataEnd,
        Err(source) => return SectionEnd::Corrupt { offset, source },
    };
    if saved == 0 || saved == computed {
        SectionEnd::DataEnd
    } else {
        SectionEnd::Corrupt {
            offset,
            source: mcap::McapError::BadDataCrc {
                saved,
                calculated: computed,
            },
        }
    }
}

/// Visits one schema, channel or message record; returns 1 for a message, else 0.
fn visit_record<E>(
    record: &Record<'_>,
    record_offset: u64,
    visit: &mut impl FnMut(DataItem<'_>) -> Result<(), E>,
) -> Result<u64, WalkError<E>> {
    let (item, is_message) = match record {
        Record::Schema { header, data } => (
            DataItem::Schema {
                id: header.id,
                name: &header.name,
                encoding: &header.encoding,
                data,
            },
            0,
        ),
        Record::Channel(channel) => (
            DataItem::Channel {
                record_offset,
                channel,
            },
            0,
        ),
        Record::Message { header, data } => (
            DataItem::Message {
                record_offset,
                header,
                data,
            },
            1,
        ),
        _ => return Ok(0),
    };
    visit(item).map_err(WalkError::Visit)?;
    Ok(is_message)
}
