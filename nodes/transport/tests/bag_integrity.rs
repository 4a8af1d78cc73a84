//! A bag whose bytes changed after it was written is refused, naming the file and the byte
//! offset, even where no chunk CRC covers the change: the data section's CRC (stored in the
//! `DataEnd` record by the writer) is checked over every byte before it.

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
            .add_channel(schema, "/rpkm/actuator_state", "json", &Default::default())
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
