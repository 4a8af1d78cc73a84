//! The request/reply wire of a service a node offers, for clients of either ROS 2 request
//! mapping, decided per request:
//!
//! - rmw_fastrtps (ROS 2's default middleware) uses DDS-RPC's "enhanced" mapping: no header
//!   in the payload; the request id is the request sample's own identity (writer GUID,
//!   sequence number), and the request carries its client's reply reader's GUID as its
//!   related sample identity (inline QoS). The reply carries (that GUID, the request's
//!   sequence number) as its related sample identity; the client matches it by that alone.
//! - rmw_cyclonedds puts a 16-byte header (client id, sequence number) before the request in
//!   the payload, sends no related sample identity, and takes a reply whose payload starts
//!   with the same header. ros2-client's clients in that mapping (`rpkm launch`) write the
//!   header and also a related sample identity equal to it.
//!
//! [`Caller::of`] tells them apart: a header that equals the request's related sample
//! identity is ros2-client's; any other related sample identity, or a writer of eProsima's
//! (a Fast DDS GUID prefix starts with its vendor id), is the enhanced mapping; the rest
//! carry the header. A request that does not decode as the service's type in the mapping so
//! chosen is counted ([`Unread`]) and never answered: a guess could set a parameter wrongly.
//!
//! A reply waits until the client's reply reader is matched (as rmw_cyclonedds's servers
//! wait): a client's first call otherwise races the discovery of its reader, and the reply
//! to a reader not yet matched is lost. A reply whose reader is not matched within
//! [`REPLY_WAIT`] is dropped, logged and counted.

use std::collections::BTreeSet;
use std::marker::PhantomData;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures::{Stream, StreamExt};
use ros2_client::dds::rustdds::{
    bytes::Bytes, no_key, rpc::SampleIdentity, DataWriterStatus, DomainParticipant, QosPolicies,
    RepresentationIdentifier, SequenceNumber, StatusEvented, TopicKind, WriteOptionsBuilder, GUID,
};
use ros2_client::QosProfile;
use serde::{de::DeserializeOwned, Serialize};

/// How long a reply waits for its client's reply reader to be matched: discovery on one
/// host takes about 0.1 s, between hosts a few tenths; a client gone for longer will not
/// read the reply.
pub(crate) const REPLY_WAIT: Duration = Duration::from_secs(3);

/// How often replies waiting for their readers look again (discovery takes about 0.1 s).
const REPLY_POLL: Duration = Duration::from_millis(10);

/// A timer for a service task's loop: it fires after [`REPLY_POLL`] while replies wait for
/// their readers (`waiting`), never otherwise (the task then sleeps until a request comes).
pub(crate) fn reply_timer(
    waiting: bool,
) -> futures::future::Fuse<futures::future::BoxFuture<'static, ()>> {
    use futures::FutureExt;
    if waiting {
        tokio::time::sleep(REPLY_POLL).boxed().fuse()
    } else {
        futures::future::Fuse::terminated()
    }
}

/// Length of rmw_cyclonedds's request header: client id (8 bytes), sequence number (8).
const HEADER_LEN: usize = 16;

/// eProsima's RTPS vendor id, the first two bytes of every Fast DDS GUID prefix.
const VENDOR_EPROSIMA: [u8; 2] = [0x01, 0x0f];

/// A sample's payload as it came: its representation and its CDR body (after the 4-byte
/// encapsulation header, which RustDDS keeps as the representation).
#[derive(Clone, Debug)]
pub(crate) struct RawSample {
    encoding: RepresentationIdentifier,
    body: Bytes,
}

/// RustDDS's adapter for [`RawSample`]: the bytes as they are, nothing decoded.
pub(crate) struct RawAdapter;

const PLAIN_CDR: [RepresentationIdentifier; 2] = [
    RepresentationIdentifier::CDR_LE,
    RepresentationIdentifier::CDR_BE,
];

impl no_key::DeserializerAdapter<RawSample> for RawAdapter {
    type Error = std::convert::Infallible;
    type Decoded = RawSample;
    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &PLAIN_CDR
    }
    fn transform_decoded(decoded: RawSample) -> RawSample {
        decoded
    }
}

/// The decoder of [`RawAdapter`]: copies the bytes.
#[derive(Clone)]
pub(crate) struct RawDecoder;

impl<'de> no_key::Decode<'de, RawSample> for RawDecoder {
    type Error = std::convert::Infallible;
    fn decode_bytes(
        self,
        input_bytes: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<RawSample, Self::Error> {
        Ok(RawSample {
            encoding,
            body: Bytes::copy_from_slice(input_bytes),
        })
    }
}

impl no_key::DefaultDecoder<RawSample> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

impl no_key::SerializerAdapter<RawSample> for RawAdapter {
    type Error = std::convert::Infallible;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &RawSample) -> Result<Bytes, Self::Error> {
        Ok(value.body.clone())
    }
}

/// Who sent a request, in the mapping its client reads the reply in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Caller {
    /// rmw_cyclonedds's mapping: the reply's payload starts with these 16 bytes, as the
    /// request's did; the client's reply reader lives in the request writer's participant.
    Header {
        header: [u8; HEADER_LEN],
        writer: GUID,
    },
    /// The enhanced mapping: the reply's related sample identity; its GUID is the client's
    /// reply reader where the request named it, else the request writer.
    Identity(SampleIdentity),
}

impl Caller {
    /// The mapping of a request sample (the rules of the module's doc).
    fn of(
        writer: GUID,
        sequence: SequenceNumber,
        related: Option<SampleIdentity>,
        body: &[u8],
    ) -> Self {
        let header = body
            .get(..HEADER_LEN)
            .and_then(|h| <[u8; HEADER_LEN]>::try_from(h).ok());
        let echoed = match (header, related) {
            (Some(h), Some(r)) => header_names(&h, r),
            _ => false,
        };
        let fast_dds = writer.to_bytes()[..2] == VENDOR_EPROSIMA;
        match (header, related) {
            (Some(header), _) if echoed => Caller::Header { header, writer },
            (_, Some(r)) => Caller::Identity(enhanced_identity(r, writer, sequence)),
            (_, None) if fast_dds => Caller::Identity(enhanced_identity(
                SampleIdentity {
                    writer_guid: GUID::GUID_UNKNOWN,
                    sequence_number: sequence,
                },
                writer,
                sequence,
            )),
            (Some(header), None) => Caller::Header { header, writer },
            (None, None) => Caller::Identity(enhanced_identity(
                SampleIdentity {
                    writer_guid: GUID::GUID_UNKNOWN,
                    sequence_number: sequence,
                },
                writer,
                sequence,
            )),
        }
    }

    /// The mapping's name, for logs and /diagnostics.
    pub(crate) fn mapping(&self) -> &'static str {
        match self {
            Caller::Header { .. } => "request header (rmw_cyclonedds)",
            Caller::Identity(_) => "sample identity (rmw_fastrtps)",
        }
    }

    /// Where the request's payload begins.
    fn body_offset(&self) -> usize {
        match self {
            Caller::Header { .. } => HEADER_LEN,
            Caller::Identity(_) => 0,
        }
    }

    /// Whether the client's reply reader is among `matched` (the reply writer's matched
    /// readers): the named reader itself, or any reader of the request writer's participant.
    fn reader_matched(&self, matched: &[GUID]) -> bool {
        let participant = |w: &GUID| {
            let bytes = w.to_bytes();
            matched.iter().any(|r| r.to_bytes()[..12] == bytes[..12])
        };
        match self {
            Caller::Header { writer, .. } => participant(writer),
            Caller::Identity(id) if id.writer_guid.entity_id.kind().is_reader() => {
                matched.contains(&id.writer_guid)
            }
            Caller::Identity(id) => participant(&id.writer_guid),
        }
    }
}

/// Whether a payload header names the request `related` names: the client GUID's last 8
/// bytes, then the sequence number as ros2-client writes it (high, then low 32 bits) or as
/// rmw_cyclonedds does (one little-endian 64-bit number).
fn header_names(header: &[u8; HEADER_LEN], related: SampleIdentity) -> bool {
    let guid = related.writer_guid.to_bytes();
    let seq = i64::from(related.sequence_number);
    let word = |at: usize| {
        let mut w = [0u8; 4];
        w.copy_from_slice(&header[at..at + 4]);
        u32::from_le_bytes(w)
    };
    let split = (i64::from(word(8).cast_signed()) << 32) | i64::from(word(12));
    let mut whole = [0u8; 8];
    whole.copy_from_slice(&header[8..]);
    header[..8] == guid[8..] && (split == seq || i64::from_le_bytes(whole) == seq)
}

/// The enhanced mapping's reply identity: the reply reader's GUID where the request named
/// one (else the request writer's), with the request sample's own sequence number (rmw_fastrtps
/// leaves the related identity's number unknown).
fn enhanced_identity(
    related: SampleIdentity,
    writer: GUID,
    sequence: SequenceNumber,
) -> SampleIdentity {
    let writer_guid = if related.writer_guid == GUID::GUID_UNKNOWN {
        writer
    } else {
        related.writer_guid
    };
    SampleIdentity {
        writer_guid,
        sequence_number: sequence,
    }
}

/// Requests of one service that could not be read: how many, and the last reason.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Unread {
    /// The service (`/rpkm/ingest/get_parameters`).
    pub service: String,
    /// Requests unread since the node started.
    pub count: u64,
    /// Why the last one could not be read (its mapping and the decoder's message).
    pub reason: String,
    /// Replies dropped because the client's reply reader was never matched.
    pub replies_lost: u64,
}

/// The unread requests of every service of a node, shared with the node's /diagnostics.
pub(crate) type Ledger = Arc<Mutex<Vec<Unread>>>;

/// A reply waiting for its client's reply reader to be matched.
struct Pending {
    caller: Caller,
    payload: Bytes,
    since: Instant,
}

/// One service's request reader and reply writer (`rq/<service>Request`, `rr/<service>Reply`).
pub(crate) struct RpcServer<Q, R> {
    requests: no_key::SimpleDataReader<RawSample, RawAdapter>,
    replies: no_key::DataWriter<RawSample, RawAdapter>,
    /// The readers the reply writer is matched with, from its match events (RustDDS's
    /// list of matched subscriptions is not implemented).
    matched: Mutex<BTreeSet<GUID>>,
    pending: Mutex<Vec<Pending>>,
    /// Whether a fragmented reply on the enhanced mapping was said (once per service).
    said_fragmented: std::sync::atomic::AtomicBool,
    ledger: Ledger,
    name: String,
    types: PhantomData<fn(Q) -> R>,
}

/// The DDS type names of a service's request and reply (`pkg::srv::dds_::Name_Request_`).
#[derive(Debug, Clone)]
pub(crate) struct RpcTypes {
    pub request: String,
    pub reply: String,
}

impl RpcTypes {
    /// A service type `package/srv/name` (`kind` `srv`) or an action's service
    /// (`package/action/Name_SendGoal`, `kind` `action`).
    pub(crate) fn new(package: &str, kind: &str, name: &str) -> Self {
        Self {
            request: format!("{package}::{kind}::dds_::{name}_Request_"),
            reply: format!("{package}::{kind}::dds_::{name}_Response_"),
        }
    }
}

/// rmw's service QoS: reliable, volatile, keep last 10.
fn service_qos() -> QosPolicies {
    let qos =
        QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth: 10 });
    QosPolicies::from(&qos)
}

impl<Q: DeserializeOwned, R: Serialize> RpcServer<Q, R> {
    /// The server of the service `name` (fully qualified, `/rpkm/ingest/get_state`).
    pub(crate) fn new(
        participant: &DomainParticipant,
        name: &str,
        types: &RpcTypes,
        ledger: Ledger,
    ) -> Result<Self, String> {
        let qos = service_qos();
        let e = |what: &str, err: &dyn std::fmt::Display| format!("{name}: {what}: {err}");
        let rq = participant
            .create_topic(
                format!("rq{name}Request"),
                types.request.clone(),
                &qos,
                TopicKind::NoKey,
            )
            .map_err(|err| e("request topic", &err))?;
        let rr = participant
            .create_topic(
                format!("rr{name}Reply"),
                types.reply.clone(),
                &qos,
                TopicKind::NoKey,
            )
            .map_err(|err| e("reply topic", &err))?;
        let requests = participant
            .create_subscriber(&qos)
            .and_then(|s| s.create_simple_datareader_no_key::<RawSample, RawAdapter>(&rq, None))
            .map_err(|err| e("request reader", &err))?;
        let replies = participant
            .create_publisher(&qos)
            .and_then(|p| p.create_datawriter_no_key::<RawSample, RawAdapter>(&rr, None))
            .map_err(|err| e("reply writer", &err))?;
        Ok(Self {
            requests,
            replies,
            matched: Mutex::new(BTreeSet::new()),
            pending: Mutex::new(Vec::new()),
            said_fragmented: std::sync::atomic::AtomicBool::new(false),
            ledger,
            name: name.to_owned(),
            types: PhantomData,
        })
    }

    /// The service's name.
    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    /// The next request waiting, if any (the node's loop polls); unreadable ones are
    /// counted and skipped.
    pub(crate) fn try_next(&self) -> Option<(Caller, Q)> {
        self.requests.drain_read_notifications();
        loop {
            match self.requests.try_take_one() {
                Ok(Some(sample)) => {
                    if let Some(request) = self.read(&sample) {
                        return Some(request);
                    }
                }
                Ok(None) => return None,
                Err(e) => {
                    self.unread("", &format!("reading the request: {e:?}"));
                    return None;
                }
            }
        }
    }

    /// Every request as it comes (a task on the node's runtime awaits them); unreadable ones
    /// are counted and skipped.
    pub(crate) fn stream(&self) -> impl Stream<Item = (Caller, Q)> + '_ {
        self.requests
            .as_async_stream()
            .filter_map(move |sample| async move {
                match sample {
                    Ok(sample) => self.read(&sample),
                    Err(e) => {
                        self.unread("", &format!("reading the request: {e:?}"));
                        None
                    }
                }
            })
    }

    fn read(&self, sample: &no_key::DeserializedCacheChange<RawSample>) -> Option<(Caller, Q)> {
        let raw = &sample.sample;
        let caller = Caller::of(
            sample.writer_guid,
            sample.sequence_number,
            sample.write_options.related_sample_identity(),
            &raw.body,
        );
        match decode::<Q>(raw, caller) {
            Ok(request) => Some((caller, request)),
            Err(reason) => {
                self.unread(caller.mapping(), &reason);
                None
            }
        }
    }

    fn unread(&self, mapping: &str, reason: &str) {
        let reason = if mapping.is_empty() {
            reason.to_owned()
        } else {
            format!("as {mapping}: {reason}")
        };
        log::warn!(
            "service {}: request not read, not answered: {reason}",
            self.name
        );
        self.tally(|u| {
            u.count += 1;
            u.reason = reason;
        });
    }

    fn tally(&self, change: impl FnOnce(&mut Unread)) {
        if let Ok(mut ledger) = self.ledger.lock() {
            if let Some(u) = ledger.iter_mut().find(|u| u.service == self.name) {
                change(u);
            } else {
                let mut u = Unread {
                    service: self.name.clone(),
                    ..Unread::default()
                };
                change(&mut u);
                ledger.push(u);
            }
        }
    }

    /// Answers `caller` with `response`: now if its reply reader is matched, else when it
    /// is ([`Self::flush`]).
    pub(crate) fn reply(&self, caller: Caller, response: &R) {
        let payload = match encode(caller, response) {
            Ok(p) => p,
            Err(e) => {
                log::warn!("service {}: reply not encoded: {e}", self.name);
                return;
            }
        };
        if let Ok(mut pending) = self.pending.lock() {
            pending.push(Pending {
                caller,
                payload,
                since: Instant::now(),
            });
        }
        self.flush();
    }

    /// The reply writer's match events as they come (a task awaits them beside the
    /// requests): each updates the matched readers and sends the replies that waited for it.
    pub(crate) fn matches(&self) -> impl Stream<Item = ()> + '_ {
        self.replies.as_async_status_stream().map(move |status| {
            self.note(&status);
            self.flush();
        })
    }

    /// Takes a match event into the matched readers (RustDDS keeps four events: a server
    /// polled from a node's loop takes them at each poll, a task as they come).
    fn note(&self, status: &DataWriterStatus) {
        match status {
            DataWriterStatus::PublicationMatched {
                current, reader, ..
            } => {
                if let Ok(mut matched) = self.matched.lock() {
                    if current.count_change() > 0 {
                        matched.insert(*reader);
                    } else if current.count_change() < 0 {
                        matched.remove(reader);
                    }
                }
            }
            DataWriterStatus::OfferedIncompatibleQos { reader, .. } => log::warn!(
                "service {}: a client's reply reader {reader:?} requests a QoS the reply \
                 writer does not offer (reliable, volatile): it gets no reply",
                self.name
            ),
            _ => {}
        }
    }

    /// Whether replies wait for their readers.
    pub(crate) fn waiting(&self) -> bool {
        self.pending.lock().is_ok_and(|p| !p.is_empty())
    }

    /// Sends the replies whose reader is matched; drops those that waited [`REPLY_WAIT`].
    pub(crate) fn flush(&self) {
        let Ok(mut pending) = self.pending.lock() else {
            return;
        };
        while let Some(status) = self.replies.try_recv_status() {
            self.note(&status);
        }
        if pending.is_empty() {
            return;
        }
        let matched: Vec<GUID> = self
            .matched
            .lock()
            .map(|m| m.iter().copied().collect())
            .unwrap_or_default();
        let mut lost = 0;
        pending.retain(|p| {
            if p.caller.reader_matched(&matched) {
                self.send(p);
                false
            } else if p.since.elapsed() > REPLY_WAIT {
                lost += 1;
                false
            } else {
                true
            }
        });
        drop(pending);
        if lost > 0 {
            log::warn!(
                "service {}: {lost} replies dropped: the client's reply reader was not matched \
                 within {} s",
                self.name,
                REPLY_WAIT.as_secs()
            );
            self.tally(|u| u.replies_lost += lost);
        }
    }

    fn send(&self, p: &Pending) {
        let options = match p.caller {
            Caller::Identity(id) => {
                self.say_if_fragmented(p.payload.len());
                WriteOptionsBuilder::new().related_sample_identity(id)
            }
            Caller::Header { .. } => WriteOptionsBuilder::new(),
        };
        let sample = RawSample {
            encoding: RepresentationIdentifier::CDR_LE,
            body: p.payload.clone(),
        };
        if let Err(e) = self.replies.write_with_options(sample, options.build()) {
            log::warn!("service {}: reply not sent: {e}", self.name);
        }
    }
}

impl<Q, R> RpcServer<Q, R> {
    /// Says once per service when a reply on the enhanced mapping is larger than one datagram
    /// of this host's network paths: it then goes as fragments with inline QoS, which RustDDS
    /// 0.15.1 writes malformed ([`crate::dds_wire`]): a client on loopback reads it, one
    /// reached through a network interface does not.
    fn say_if_fragmented(&self, body_len: usize) {
        // the 4-byte encapsulation header goes with the body
        let len = body_len + 4;
        let limit = crate::dds_wire::inline_qos_limit();
        if len > limit
            && !self
                .said_fragmented
                .swap(true, std::sync::atomic::Ordering::Relaxed)
        {
            log::warn!(
                "service {}: a {len}-byte reply to an rmw_fastrtps client is above this host's \
                 {limit}-byte datagram: through a network interface it goes as fragments whose \
                 related sample identity RustDDS 0.15.1 writes malformed, and the client does \
                 not read it (on loopback it goes whole)",
                self.name
            );
        }
    }
}

/// The request in `raw` as `caller`'s mapping lays it out.
fn decode<Q: DeserializeOwned>(raw: &RawSample, caller: Caller) -> Result<Q, String> {
    let body = raw.body.get(caller.body_offset()..).unwrap_or_default();
    let big_endian = raw.encoding == RepresentationIdentifier::CDR_BE;
    if big_endian && matches!(caller, Caller::Header { .. }) {
        return Err("a big-endian request with a payload header (not supported)".into());
    }
    let decoded = if big_endian {
        cdr_encoding::from_bytes::<Q, byteorder::BigEndian>(body)
    } else {
        cdr_encoding::from_bytes::<Q, byteorder::LittleEndian>(body)
    };
    decoded
        .map(|(q, _)| q)
        .map_err(|e| format!("{} bytes do not decode: {e}", body.len()))
}

/// The reply payload (little-endian CDR body) for `caller`: its header first where its
/// mapping has one. The header is 16 bytes, so the response keeps its CDR alignment.
fn encode<R: Serialize>(caller: Caller, response: &R) -> Result<Bytes, String> {
    let mut out = match caller {
        Caller::Header { header, .. } => header.to_vec(),
        Caller::Identity(_) => Vec::new(),
    };
    cdr_encoding::to_writer::<R, byteorder::LittleEndian, _>(&mut out, response)
        .map_err(|e| e.to_string())?;
    Ok(Bytes::from(out))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// RTPS entity kinds: a user-defined writer and reader without key.
    const WRITER: u8 = 0x03;
    const READER: u8 = 0x04;

    fn guid(prefix: [u8; 12], kind: u8) -> GUID {
        let mut bytes = [0u8; 16];
        bytes[..12].copy_from_slice(&prefix);
        bytes[12..].copy_from_slice(&[0, 0, 7, kind]);
        GUID::from_bytes(bytes)
    }

    const FAST: [u8; 12] = [0x01, 0x0f, 9, 9, 9, 9, 9, 9, 1, 0, 0, 0];
    const CYCLONE: [u8; 12] = [0xa7, 0x31, 0x10, 0x2c, 5, 6, 7, 8, 9, 10, 11, 12];

    /// rmw_fastrtps: related identity = the reply reader, its number unknown; the reply
    /// identity is that reader with the request's own number, the payload has no header.
    #[test]
    fn a_fast_dds_request_is_answered_by_identity() {
        let writer = guid(FAST, WRITER);
        let reader = guid(FAST, READER);
        let related = SampleIdentity {
            writer_guid: reader,
            sequence_number: SequenceNumber::from(-1_i64),
        };
        // GetState's request is empty: no header could precede it.
        let caller = Caller::of(writer, SequenceNumber::from(3_i64), Some(related), &[]);
        let Caller::Identity(id) = caller else {
            panic!("{caller:?}")
        };
        assert_eq!((id.writer_guid, i64::from(id.sequence_number)), (reader, 3));
        assert!(caller.reader_matched(&[reader]));
        assert!(!caller.reader_matched(&[guid(CYCLONE, READER)]));
    }

    /// rmw_cyclonedds: no related identity, the header echoed in the reply's payload.
    #[test]
    fn a_cyclone_request_is_answered_by_its_header() {
        let writer = guid(CYCLONE, WRITER);
        let mut body = vec![0xab; HEADER_LEN];
        // ListParameters's request: no prefixes, depth 5 (8-aligned after the header).
        body.extend_from_slice(&[0, 0, 0, 0, 0xee, 0xee, 0xee, 0xee, 5, 0, 0, 0, 0, 0, 0, 0]);
        let caller = Caller::of(writer, SequenceNumber::from(1_i64), None, &body);
        assert!(matches!(caller, Caller::Header { header, .. } if header == [0xab; 16]));
        let reply = encode(caller, &7_u32).expect("encode");
        assert_eq!(&reply[..HEADER_LEN], &[0xab; 16]);
        assert_eq!(&reply[HEADER_LEN..], &7_u32.to_le_bytes());
        let raw = RawSample {
            encoding: RepresentationIdentifier::CDR_LE,
            body: Bytes::from(body),
        };
        let (prefixes, depth): (Vec<String>, u64) = decode(&raw, caller).expect("decode");
        assert_eq!((prefixes.len(), depth), (0, 5));
        // Its reply reader is any reader of the writer's participant.
        assert!(caller.reader_matched(&[guid(CYCLONE, READER)]));
    }

    /// ros2-client's Cyclone-mapped client writes the header and the same identity inline.
    #[test]
    fn a_header_that_equals_the_identity_is_the_header_mapping() {
        let prefix = [0x01, 0x12, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10];
        let writer = guid(prefix, WRITER);
        let related = SampleIdentity {
            writer_guid: writer,
            sequence_number: SequenceNumber::from(0x1_0000_0002_i64),
        };
        let mut body = writer.to_bytes()[8..].to_vec();
        body.extend_from_slice(&1_i32.to_le_bytes());
        body.extend_from_slice(&2_u32.to_le_bytes());
        let caller = Caller::of(writer, SequenceNumber::from(9_i64), Some(related), &body);
        assert!(matches!(caller, Caller::Header { .. }), "{caller:?}");
    }
}
