//! Writing bags with `BagWriter` and reading them back with `BagReader`.

mod bag_common;

use bag_common::{drive_sample, event, DriveSample, Event};
use rpkm_msgs::RosMessage;
use rpkm_transport::bag::{
    BagCompression, BagDecodeError, BagOpenError, BagReader, BagWriteError, BagWriter,
    BagWriterOptions, QosProfile, RawTopic,
};

fn write_mixed(dir: &std::path::Path, options: BagWriterOptions, n: u64) {
    let mut bag = BagWriter::create(dir, options).expect("create bag");
    let drives = bag
        .add_topic::<DriveSample>("/drives", &QosProfile::sensor_data())
        .expect("add /drives");
    let events = bag
        .add_topic::<Event>("/events", &QosProfile::default())
        .expect("add /events");
    for i in 0..n {
        let (t, s) = drive_sample(i);
        bag.write(&drives, t, &s).expect("write drive");
        if i % 8 == 0 {
            let (t, e) = event(i / 8);
            bag.write(&events, t, &e).expect("write event");
        }
    }
    let summary = bag.finish().expect("finish");
    assert_eq!(summary.topics[0], ("/drives".to_owned(), n));
}

fn check_mixed(dir: &std::path::Path, n: u64) {
    let reader = BagReader::open(dir).expect("open");
    let topics = reader.topics();
    assert_eq!(topics.len(), 2);
    assert_eq!(topics[0].name, "/drives");
    assert_eq!(topics[0].type_name, "rpkm_test_msgs/msg/DriveSample");
    assert_eq!(topics[0].message_count, n);
    assert_eq!(topics[0].definition, DriveSample::definition());
    assert_eq!(topics[0].schema_encoding, "ros2msg");
    assert_eq!(topics[0].message_encoding, "cdr");
    assert_eq!(
        topics[0].offered_qos_profiles,
        QosProfile::sensor_data().to_rosbag2_yaml()
    );
    assert_eq!(topics[1].message_count, n.div_ceil(8));

    let mut last = 0;
    let mut seen_drives = 0;
    for message in reader.messages() {
        let message = message.expect("read");
        assert!(message.log_time >= last, "log-time order");
        last = message.log_time;
        if message.topic == "/drives" {
            let value: DriveSample = message.decode().expect("decode drive");
            assert_eq!(u64::from(message.sequence), seen_drives);
            let (t, expected) = drive_sample(seen_drives);
            assert_eq!(message.log_time, t);
            assert_eq!(message.publish_time, t);
            assert_eq!(value, expected);
            seen_drives += 1;
        }
    }
    assert_eq!(seen_drives, n);
    let events = reader.decode_topic::<Event>("/events").expect("events");
    for (i, (t, e)) in events.iter().enumerate() {
        let (et, ee) = event(i as u64);
        assert_eq!((*t, e), (et, &ee));
    }

    let meta = reader.metadata().expect("metadata.yaml");
    assert_eq!(meta.version, 8);
    assert_eq!(meta.storage_identifier, "mcap");
    assert_eq!(meta.message_count, n + n.div_ceil(8));
    let (first, last) = reader.time_bounds().expect("non-empty");
    assert_eq!(meta.starting_time.nanoseconds_since_epoch, first);
    assert_eq!(meta.duration.nanoseconds, last - first);
    let name = dir.file_name().and_then(|n| n.to_str()).expect("name");
    assert_eq!(meta.relative_file_paths, vec![format!("{name}_0.mcap")]);
}

#[test]
fn uncompressed_small_chunks_round_trip() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("plain");
    let options = BagWriterOptions {
        chunk_size: 4096,
        ..Default::default()
    };
    write_mixed(&dir, options, 3000);
    check_mixed(&dir, 3000);
}

#[test]
fn zstd_and_lz4_round_trip() {
    for (name, compression) in [("z", BagCompression::Zstd), ("l", BagCompression::Lz4)] {
        let tmp = tempfile::tempdir().expect("tempdir");
        let dir = tmp.path().join(name);
        let options = BagWriterOptions {
            compression,
            chunk_size: 64 * 1024,
            ..Default::default()
        };
        write_mixed(&dir, options, 2000);
        check_mixed(&dir, 2000);
    }
}

#[test]
fn bare_mcap_file_opens_without_metadata() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("bare");
    write_mixed(&dir, BagWriterOptions::default(), 100);
    let reader = BagReader::open(dir.join("bare_0.mcap")).expect("open file");
    assert!(reader.metadata().is_none());
    assert_eq!(reader.message_count(), 100 + 13);
}

#[test]
fn empty_bag_is_valid() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("empty");
    let mut bag = BagWriter::create(&dir, BagWriterOptions::default()).expect("create");
    bag.add_topic::<Event>("/events", &QosProfile::default())
        .expect("topic");
    bag.finish().expect("finish");
    let reader = BagReader::open(&dir).expect("open");
    assert_eq!(reader.message_count(), 0);
    assert_eq!(reader.topics()[0].message_count, 0);
    assert_eq!(reader.time_bounds(), None);
}

#[test]
fn raw_writes_and_out_of_order_times_are_sorted() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("raw");
    let mut bag = BagWriter::create(&dir, BagWriterOptions::default()).expect("create");
    let handle = bag
        .add_topic_raw(RawTopic {
            name: "/events".into(),
            type_name: Event::type_name(),
            definition: Event::definition(),
            offered_qos_yaml: QosProfile::default().to_rosbag2_yaml(),
            type_hash: Some("RIHS01_00".into()),
        })
        .expect("raw topic");
    let mut buf = Vec::new();
    for (i, t) in [30u64, 10, 20].into_iter().enumerate() {
        let (_, e) = event(i as u64);
        rpkm_transport::bag::encode_cdr(&e, &mut buf).expect("encode");
        bag.write_raw(handle, t, t + 1, &buf).expect("raw write");
    }
    bag.finish().expect("finish");
    let reader = BagReader::open(&dir).expect("open");
    assert_eq!(reader.topics()[0].type_hash.as_deref(), Some("RIHS01_00"));
    let order: Vec<(u64, u32)> = reader
        .messages()
        .map(|m| m.expect("read"))
        .map(|m| (m.log_time, m.sequence))
        .collect();
    assert_eq!(order, vec![(10, 1), (20, 2), (30, 0)]);
}

#[test]
fn decode_with_wrong_type_names_topic() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("wrong");
    write_mixed(&dir, BagWriterOptions::default(), 10);
    let reader = BagReader::open(&dir).expect("open");
    let first = reader.messages().next().expect("a message").expect("read");
    match first.decode::<Event>() {
        Err(BagDecodeError::TypeMismatch { topic, index, .. }) => {
            assert_eq!((topic.as_str(), index), ("/drives", 0));
        }
        other => panic!("expected a type mismatch, got {other:?}"),
    }
    assert!(matches!(
        reader.decode_topic::<Event>("/nope"),
        Err(BagDecodeError::NoSuchTopic { .. })
    ));
}

#[test]
fn corrupt_payload_is_an_error_with_position() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("badpayload");
    let mut bag = BagWriter::create(&dir, BagWriterOptions::default()).expect("create");
    let drives = bag
        .add_topic::<DriveSample>("/drives", &QosProfile::default())
        .expect("topic");
    bag.write_raw(drives.raw(), 5, 5, &[0, 1, 0, 0, 1, 2, 3])
        .expect("raw write");
    bag.finish().expect("finish");
    let reader = BagReader::open(&dir).expect("open");
    let message = reader
        .messages()
        .next()
        .expect("one message")
        .expect("read");
    let err = message.decode::<DriveSample>().expect_err("truncated CDR");
    let text = err.to_string();
    assert!(
        text.contains("/drives") && text.contains("message 0"),
        "{text}"
    );
}

#[test]
fn topic_conflicts_and_foreign_handles_are_refused() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let mut a = BagWriter::create(tmp.path().join("a"), BagWriterOptions::default()).expect("a");
    let mut b = BagWriter::create(tmp.path().join("b"), BagWriterOptions::default()).expect("b");
    let ha = a
        .add_topic::<Event>("/e", &QosProfile::default())
        .expect("a topic");
    assert!(matches!(
        a.add_topic::<DriveSample>("/e", &QosProfile::default()),
        Err(BagWriteError::TopicTypeConflict { .. })
    ));
    assert_eq!(
        a.add_topic::<Event>("/e", &QosProfile::default())
            .expect("same topic again")
            .raw(),
        ha.raw()
    );
    let (t, e) = event(0);
    assert!(matches!(
        b.write(&ha, t, &e),
        Err(BagWriteError::ForeignHandle { .. })
    ));
    assert!(matches!(
        BagWriter::create(tmp.path().join("a"), BagWriterOptions::default()),
        Err(BagWriteError::AlreadyExists { .. })
    ));
}

/// Every prefix and every single-byte corruption of a small bag either opens or fails with an
/// error: the reader never panics on a damaged file.
#[test]
fn damaged_files_never_panic() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("src");
    write_mixed(
        &dir,
        BagWriterOptions {
            chunk_size: 512,
            ..Default::default()
        },
        40,
    );
    let bytes = std::fs::read(dir.join("src_0.mcap")).expect("read");
    let victim = tmp.path().join("victim.mcap");
    let mut truncated = 0;
    for len in (0..bytes.len()).step_by(7) {
        std::fs::write(&victim, &bytes[..len]).expect("write prefix");
        if let Err(BagOpenError::Truncated { .. }) = BagReader::open(&victim) {
            truncated += 1;
        }
    }
    assert!(truncated > 0);
    for pos in (0..bytes.len()).step_by(3) {
        let mut damaged = bytes.clone();
        damaged[pos] ^= 0x5a;
        std::fs::write(&victim, &damaged).expect("write damaged");
        if let Ok(reader) = BagReader::open(&victim) {
            for message in reader.messages() {
                // the file did not change since it opened: every chunk reads back
                let message = message.expect("a bag that opened reads to its end");
                let _ = message.decode::<DriveSample>();
            }
        }
    }
}
