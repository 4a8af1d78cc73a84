//! A bag whose bytes changed after it was written is refused, naming the file and the byte
//! offset, even where no chunk CRC covers the change: the data section's CRC (stored in the
//! `DataEnd` record by the writer) is checked over every byte before it.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use rpkm_transport::bag::{BagOpenError, BagReader};
use std::path::{Path, PathBuf};

/// A copy of the reference calibration bag in a fresh folder; returns the folder and its
/// MCAP file.
fn copy_of_reference(name: &str) -> (PathBuf, PathBuf) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bags/calibration");
    let dir = std::env::temp_dir().join(format!("rpkm-integrity-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let mut mcap = None;
    for entry in std::fs::read_dir(&src).expect("reference bag") {
        let path = entry.expect("entry").path();
        let to = dir.join(path.file_name().expect("file name"));
        std::fs::copy(&path, &to).expect("copy");
        if to.extension().is_some_and(|e| e == "mcap") {
            mcap = Some(to);
        }
    }
    (
        dir.clone(),
        mcap.expect("an .mcap file in the reference bag"),
    )
}

#[test]
fn the_untouched_copy_opens() {
    let (dir, _) = copy_of_reference("untouched");
    BagReader::open(&dir).expect("the reference bag opens");
}

/// The Header record (right after the 8-byte magic: opcode, u64 length, profile string) is
/// not inside any chunk: one changed letter of its profile is seen only by the data CRC.
#[test]
fn a_change_outside_every_chunk_fails_the_data_section_crc() {
    let (dir, mcap) = copy_of_reference("header");
    let mut bytes = std::fs::read(&mcap).expect("read");
    assert_eq!(bytes[8], 0x01, "a Header record follows the magic");
    let profile_start = 8 + 1 + 8 + 4;
    assert_eq!(&bytes[profile_start..profile_start + 4], b"ros2");
    bytes[profile_start] = b's';
    std::fs::write(&mcap, &bytes).expect("write");
    match BagReader::open(&dir) {
        Err(BagOpenError::Corrupt {
            path,
            offset,
            source,
        }) => {
            assert_eq!(path, mcap);
            assert!(offset > 8, "the DataEnd record's offset, got {offset}");
            assert!(
                matches!(source, mcap::McapError::BadDataCrc { .. }),
                "{source}"
            );
        }
        Err(other) => panic!("refused for another reason: {other}"),
        Ok(_) => panic!("a changed byte was accepted"),
    }
}

/// A channel whose messages are JSON (another tool's bag on an rpkm topic) is refused with
/// its topic named, never decoded as CDR.
#[test]
fn a_channel_in_another_encoding_is_refused_naming_its_topic() {
    let dir = std::env::temp_dir().join(format!("rpkm-integrity-{}-json", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let file = dir.join("json.mcap");
    {
        let out = std::io::BufWriter::new(std::fs::File::create(&file).expect("create"));
        let mut w = mcap::Writer::new(out).expect("writer");
        let schema = w
            .add_schema("rpkm_msgs/msg/ActuatorState", "jsonschema", b"{}")
            .expect("schema");
        let channel = w
            .add_channel(
                schema,
                "/rpkm/actuator_state",
                "json",
                &std::collections::BTreeMap::default(),
            )
            .expect("channel");
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: 0,
            log_time: 1,
            publish_time: 1,
        };
        w.write_to_known_channel(&header, br#"{"seq": 1}"#)
            .expect("message");
        w.finish().expect("finish");
    }
    let bag = BagReader::open(&file).expect("a readable MCAP file");
    let message = bag.messages().next().expect("one message").expect("read");
    let err = message
        .decode::<rpkm_msgs::ActuatorState>()
        .expect_err("JSON is not CDR");
    let text = err.to_string();
    assert!(
        text.contains("/rpkm/actuator_state") && text.contains("json"),
        "{text}"
    );
}

/// A payload that appears once in the file, to find its bytes.
const MARKER: &[u8] = b"rpkm-integrity-payload-marker";

/// A bare MCAP file with one uncompressed chunk of three messages, written without chunk CRCs
/// (the chunk's CRC field is 0, "not computed") and with or without the data section's CRC;
/// returns its path and bytes.
fn crc_less_chunk(name: &str, data_section_crc: bool) -> (PathBuf, Vec<u8>) {
    let dir = std::env::temp_dir().join(format!("rpkm-integrity-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    let file = dir.join(format!("{name}.mcap"));
    {
        let out = std::io::BufWriter::new(std::fs::File::create(&file).expect("create"));
        let mut w = mcap::WriteOptions::new()
            .compression(None)
            .calculate_chunk_crcs(false)
            .calculate_data_section_crc(data_section_crc)
            .create(out)
            .expect("writer");
        let schema = w
            .add_schema("rpkm_msgs/msg/Blob", "ros2msg", b"uint8[] data\n")
            .expect("schema");
        let channel = w
            .add_channel(
                schema,
                "/blob",
                "cdr",
                &std::collections::BTreeMap::default(),
            )
            .expect("channel");
        for (i, data) in [&b"\0\x01\0\0first"[..], MARKER, b"\0\x01\0\0third"]
            .iter()
            .enumerate()
        {
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: i as u32,
                log_time: 10 + i as u64,
                publish_time: 10 + i as u64,
            };
            w.write_to_known_channel(&header, data).expect("message");
        }
        w.finish().expect("finish");
    }
    let bytes = std::fs::read(&file).expect("read");
    (file, bytes)
}

/// Offset of the first top-level Chunk record (opcode 0x06), after the 8-byte magic.
fn first_chunk(bytes: &[u8]) -> usize {
    let mut at = 8;
    loop {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().expect("8 bytes"));
        if bytes[at] == 0x06 {
            return at;
        }
        at += 9 + len as usize;
    }
}

/// Where the marker payload starts.
fn marker_at(bytes: &[u8]) -> usize {
    bytes
        .windows(MARKER.len())
        .position(|w| w == MARKER)
        .expect("the marker payload in the file")
}

/// Issue 16's case: a chunk whose CRC field is 0 was accepted with flipped bits. The data
/// section's CRC covers it: a flipped payload bit is refused, naming the file.
#[test]
fn a_chunk_with_crc_0_and_a_flipped_payload_bit_fails_the_data_section_crc() {
    let (file, mut bytes) = crc_less_chunk("crc0-payload", true);
    let chunk = first_chunk(&bytes);
    // body: start time, end time, uncompressed size (8 bytes each), then the CRC (4 bytes)
    let crc_field = chunk + 9 + 24;
    assert_eq!(
        &bytes[crc_field..crc_field + 4],
        &[0, 0, 0, 0],
        "no chunk CRC"
    );
    let flipped = marker_at(&bytes) + 3;
    bytes[flipped] ^= 0x04;
    std::fs::write(&file, &bytes).expect("write");
    match BagReader::open(&file) {
        Err(BagOpenError::Corrupt {
            path,
            offset,
            source,
        }) => {
            assert_eq!(path, file);
            assert!(
                offset as usize > chunk,
                "DataEnd comes after the chunk: {offset}"
            );
            assert!(
                matches!(source, mcap::McapError::BadDataCrc { .. }),
                "{source}"
            );
        }
        Err(other) => panic!("refused for another reason: {other}"),
        Ok(_) => panic!("a flipped bit in a CRC-less chunk was accepted"),
    }
}

/// With neither CRC stored nothing can vouch for a payload byte, but the chunk is still
/// decompressed and every record in it parsed: a flipped bit in a message record's length is
/// refused, naming the file and the chunk's byte offset.
#[test]
fn a_chunk_with_crc_0_and_a_flipped_length_bit_is_refused_at_the_chunk() {
    let (file, mut bytes) = crc_less_chunk("crc0-framing", false);
    let chunk = first_chunk(&bytes);
    // the message record before the marker: opcode, u64 length, channel (2), sequence (4),
    // log time (8), publish time (8), then the payload
    let record = marker_at(&bytes) - (1 + 8 + 2 + 4 + 8 + 8);
    assert_eq!(bytes[record], 0x05, "a Message record");
    bytes[record + 1 + 4] ^= 0x01; // length + 2^32
    std::fs::write(&file, &bytes).expect("write");
    match BagReader::open(&file) {
        Err(BagOpenError::Corrupt { path, offset, .. }) => {
            assert_eq!(path, file);
            assert_eq!(offset as usize, chunk, "the chunk holding the record");
        }
        Err(other) => panic!("refused for another reason: {other}"),
        Ok(_) => panic!("a broken record in a CRC-less chunk was accepted"),
    }
}
