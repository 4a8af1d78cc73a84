//! The messages of an open bag in log-time order, read from its files as they go.
//!
//! A k-way merge over the bag's segments (chunks, or message records outside any chunk): a
//! segment is read, decompressed and sorted only when its first log time comes up, and dropped
//! when its last message has gone out. rosbag2 writes chunks in time order, so one or two
//! segments are held at a time; chunks that overlap in time (a foreign writer's per-topic
//! chunks, several files over the same span) are held together, as the order requires. A
//! thread reads the segments one ahead of the merge, in the same order.

use std::cmp::Ordering;
use std::collections::binary_heap::PeekMut;
use std::collections::{BinaryHeap, VecDeque};
use std::fs::File;
use std::io::{BufReader, Seek, SeekFrom};
use std::path::Path;
use std::sync::mpsc::{self, Receiver};
use std::sync::Arc;
use std::thread::JoinHandle;

use mcap::records::Record;

use super::error::BagDecodeError;
use super::error::BagReadError;
use super::reader::{BagMessage, BagReader, ChunkIndex, Segment};
use super::records::{read_segment, SegmentError};
use rpkm_msgs::RosMessage;

/// A message read from a segment, not yet handed out.
struct Pending {
    topic: usize,
    log_time: u64,
    publish_time: u64,
    sequence: u32,
    data: Vec<u8>,
}

/// A segment being merged: its messages still to go, sorted by log time (ties in file order).
struct Active {
    /// Position of the segment in file order: breaks ties between segments.
    ordinal: usize,
    file: usize,
    offset: u64,
    queue: VecDeque<Pending>,
}

impl Active {
    /// The merge key of the next message: never empty while in the heap.
    fn key(&self) -> (u64, usize) {
        (
            self.queue.front().map_or(u64::MAX, |m| m.log_time),
            self.ordinal,
        )
    }
}

impl PartialEq for Active {
    fn eq(&self, other: &Self) -> bool {
        self.key() == other.key()
    }
}

impl Eq for Active {}

impl PartialOrd for Active {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Active {
    /// Reversed: `BinaryHeap` is a max-heap, the merge wants the smallest key on top.
    fn cmp(&self, other: &Self) -> Ordering {
        other.key().cmp(&self.key())
    }
}

/// A storage file opened for reading segments back.
struct OpenFile {
    reader: BufReader<File>,
    /// Where the reader is; `None` after a failed read.
    position: Option<u64>,
    len: u64,
}

/// Reads segments back from the storage files, in the order of the bag's schedule.
struct SegmentReader {
    index: Arc<ChunkIndex>,
    files: Vec<Option<OpenFile>>,
}

impl SegmentReader {
    fn new(index: Arc<ChunkIndex>) -> Self {
        let files = index.files.iter().map(|_| None).collect();
        Self { index, files }
    }

    /// Reads the `n`-th segment of the schedule into its sorted queue of messages.
    fn read_scheduled(&mut self, n: usize) -> Result<Active, BagReadError> {
        let index = Arc::clone(&self.index);
        let ordinal = index.schedule[n];
        let segment = index.segments[ordinal];
        let path = index.files[segment.file].as_path();
        let offset = segment.offset;
        let changed = |what: String| BagReadError::Changed {
            path: path.to_path_buf(),
            offset,
            what,
        };
        let records = self.read_records(segment.file, offset)?;
        let mut queue = VecDeque::with_capacity(records.len());
        for record in records {
            let Record::Message { header, data } = record else {
                continue;
            };
            let topic = index
                .channels
                .get(segment.file)
                .and_then(|channels| channels.get(&header.channel_id))
                .ok_or_else(|| changed(format!("unknown channel {}", header.channel_id)))?;
            queue.push_back(Pending {
                topic: *topic,
                log_time: header.log_time,
                publish_time: header.publish_time,
                sequence: header.sequence,
                data: data.into_owned(),
            });
        }
        if queue.len() as u64 != segment.messages {
            return Err(changed(format!(
                "{} messages, {} when opened",
                queue.len(),
                segment.messages
            )));
        }
        // Stable: equal log times keep their order in the chunk.
        queue.make_contiguous().sort_by_key(|m| m.log_time);
        Ok(Active {
            ordinal,
            file: segment.file,
            offset,
            queue,
        })
    }

    /// The records of the top-level record at `offset` of file `file`.
    fn read_records(
        &mut self,
        file: usize,
        offset: u64,
    ) -> Result<Vec<Record<'static>>, BagReadError> {
        let path = self.index.files[file].as_path();
        let io_err = |source| BagReadError::Io {
            path: path.to_path_buf(),
            offset,
            source,
        };
        let open = match &mut self.files[file] {
            Some(open) => open,
            slot => slot.insert(open_file(path).map_err(io_err)?),
        };
        match open.position {
            Some(position) if position == offset => {}
            // Relative: a nearby record (the next message outside chunks) stays in the buffer.
            Some(position) if position.abs_diff(offset) < 1 << 40 => {
                // Both below 2^63 (file offsets), their difference below 2^40.
                let delta = offset.cast_signed() - position.cast_signed();
                open.reader.seek_relative(delta).map_err(io_err)?;
            }
            _ => {
                open.reader.seek(SeekFrom::Start(offset)).map_err(io_err)?;
            }
        }
        // Unknown until the read succeeds.
        open.position = None;
        let available = open.len.saturating_sub(offset);
        let read = read_segment(&mut open.reader, available);
        let (consumed, records) = read.map_err(|err| match err {
            SegmentError::Io(source) => io_err(source),
            SegmentError::PastEnd { missing } => BagReadError::Changed {
                path: path.to_path_buf(),
                offset,
                what: format!("the record runs {missing} bytes past the end of the file"),
            },
            SegmentError::Corrupt(source) => BagReadError::Corrupt {
                path: path.to_path_buf(),
                offset,
                source,
            },
        })?;
        open.position = Some(offset + consumed);
        Ok(records)
    }
}

fn open_file(path: &Path) -> std::io::Result<OpenFile> {
    let file = File::open(path)?;
    let len = file.metadata()?.len();
    Ok(OpenFile {
        reader: BufReader::with_capacity(1 << 16, file),
        position: Some(0),
        len,
    })
}

/// The thread that reads the next segments while the merge hands out messages, so that a
/// chunk's reading (milliseconds) never stalls a timed consumer such as `rpkm replay`.
struct ReadAhead {
    segments: Receiver<Result<Active, BagReadError>>,
    thread: JoinHandle<()>,
}

/// Segments read ahead of the merge: one waiting in the channel, one being read.
const READ_AHEAD: usize = 1;

impl ReadAhead {
    fn start(index: Arc<ChunkIndex>) -> std::io::Result<Self> {
        let (sender, segments) = mpsc::sync_channel(READ_AHEAD);
        let thread = std::thread::Builder::new()
            .name("rpkm-bag-read".into())
            .spawn(move || {
                let count = index.schedule.len();
                let mut reader = SegmentReader::new(index);
                for n in 0..count {
                    let segment = reader.read_scheduled(n);
                    let failed = segment.is_err();
                    // a closed channel: the iterator was dropped
                    if sender.send(segment).is_err() || failed {
                        return;
                    }
                }
            })?;
        Ok(Self { segments, thread })
    }
}

/// Iterator over a bag's messages in log-time order (ties in file order); see
/// [`BagReader::messages`]. After an error it yields nothing more.
pub struct Messages<'a> {
    bag: &'a BagReader,
    /// Started with the first message.
    read_ahead: Option<ReadAhead>,
    /// Segments of the schedule received so far.
    next_segment: usize,
    active: BinaryHeap<Active>,
    /// Messages handed out so far.
    index: usize,
    buffered_bytes: u64,
    peak_buffered_bytes: u64,
    failed: bool,
}

impl<'a> Messages<'a> {
    pub(super) fn new(bag: &'a BagReader) -> Self {
        Self {
            bag,
            read_ahead: None,
            next_segment: 0,
            active: BinaryHeap::new(),
            index: 0,
            buffered_bytes: 0,
            peak_buffered_bytes: 0,
            failed: false,
        }
    }

    /// The most payload bytes the merge held at once so far: read from the files and not yet
    /// handed out. About one chunk's messages where chunks do not overlap in time, whatever
    /// the size of the bag; the reading thread holds up to two more chunks ahead of it.
    pub fn peak_buffered_bytes(&self) -> u64 {
        self.peak_buffered_bytes
    }

    /// Takes in every segment whose first message may come before the head of the merge.
    fn activate_due(&mut self) -> Result<(), BagReadError> {
        let index = Arc::clone(self.bag.index());
        while let Some(&ordinal) = index.schedule.get(self.next_segment) {
            let segment = index.segments[ordinal];
            let due = match self.active.peek() {
                None => true,
                Some(head) => (segment.first_log_time, ordinal) < head.key(),
            };
            if !due {
                break;
            }
            let active = self.receive(&index, segment)?;
            let bytes: u64 = active.queue.iter().map(|m| m.data.len() as u64).sum();
            self.buffered_bytes += bytes;
            self.peak_buffered_bytes = self.peak_buffered_bytes.max(self.buffered_bytes);
            self.active.push(active);
            self.next_segment += 1;
        }
        Ok(())
    }

    /// The next segment of the schedule, `segment`, from the reading thread.
    fn receive(
        &mut self,
        index: &Arc<ChunkIndex>,
        segment: Segment,
    ) -> Result<Active, BagReadError> {
        let thread_error = |source| BagReadError::Io {
            path: index.files[segment.file].clone(),
            offset: segment.offset,
            source,
        };
        let read_ahead = match &mut self.read_ahead {
            Some(read_ahead) => read_ahead,
            slot => slot.insert(ReadAhead::start(Arc::clone(index)).map_err(thread_error)?),
        };
        match read_ahead.segments.recv() {
            Ok(segment) => segment,
            // only if the thread died: it sends an error before it ends otherwise
            Err(_) => Err(thread_error(std::io::Error::other(
                "the bag's reading thread stopped",
            ))),
        }
    }
}

impl Drop for Messages<'_> {
    fn drop(&mut self) {
        if let Some(ReadAhead { segments, thread }) = self.read_ahead.take() {
            // closing the channel ends the thread at its next segment
            drop(segments);
            let _ = thread.join();
        }
    }
}

impl<'a> Iterator for Messages<'a> {
    type Item = Result<BagMessage<'a>, BagReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        if let Err(err) = self.activate_due() {
            self.failed = true;
            return Some(Err(err));
        }
        let mut head = self.active.peek_mut()?;
        let (file, offset) = (head.file, head.offset);
        let pending = head.queue.pop_front()?;
        if head.queue.is_empty() {
            PeekMut::pop(head);
        }
        self.buffered_bytes -= pending.data.len() as u64;
        let bag = self.bag;
        let topic = bag.topics().get(pending.topic);
        let message = BagMessage {
            topic: topic.map_or("", |t| t.name.as_str()),
            topic_index: pending.topic,
            type_name: topic.map_or("", |t| t.type_name.as_str()),
            message_encoding: topic.map_or("", |t| t.message_encoding.as_str()),
            log_time: pending.log_time,
            publish_time: pending.publish_time,
            sequence: pending.sequence,
            data: pending.data,
            index: self.index,
            file: bag.files()[file].as_path(),
            record_offset: offset,
        };
        self.index += 1;
        Some(Ok(message))
    }
}

/// Reading a bag's messages: the merge of its segments, here where the merge is.
impl BagReader {
    /// All messages in log-time order (ties in file order), read from the files as they go.
    pub fn messages(&self) -> Messages<'_> {
        Messages::new(self)
    }

    /// Decodes every message of `topic` as `T`, with its log time, in log-time order.
    pub fn decode_topic<T: RosMessage>(
        &self,
        topic: &str,
    ) -> Result<Vec<(u64, T)>, BagDecodeError> {
        if self.topic(topic).is_none() {
            return Err(BagDecodeError::NoSuchTopic {
                topic: topic.to_owned(),
            });
        }
        let mut decoded = Vec::new();
        for message in self.messages() {
            let message = message?;
            // every type under that name: a second type is a mismatch, not skipped
            if message.topic == topic {
                decoded.push((message.log_time, message.decode::<T>()?));
            }
        }
        Ok(decoded)
    }
}
