//! Reading a bag streams: the reader holds about a chunk's messages whatever the size of the
//! bag, and the messages still come in log-time order across chunks that overlap in time.
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use std::path::{Path, PathBuf};
use std::process::Command;

use rpkm_transport::bag::{
    BagCompression, BagReadError, BagReader, BagWriter, BagWriterOptions, QosProfile, RawTopic,
};

/// Bytes of every payload: CDR header, topic number, sequence number, filler.
const PAYLOAD: usize = 1000;
/// Period of the fast topic, ns (8 kHz).
const PERIOD_NS: u64 = 125_000;
/// A message of the late topic every this many fast ones, stamped this much before the fast
/// message it is written after: a live recording's second queue, so chunks overlap in time.
const LATE_EVERY: u64 = 10;
const LATE_BY_NS: u64 = 3_000_000;

fn payload(topic: u8, seq: u64) -> Vec<u8> {
    let mut data = vec![0u8; PAYLOAD];
    data[..4].copy_from_slice(&[0, 1, 0, 0]);
    data[4] = topic;
    data[5..13].copy_from_slice(&seq.to_le_bytes());
    for (i, byte) in data[13..].iter_mut().enumerate() {
        *byte = (seq as usize).wrapping_add(i) as u8;
    }
    data
}

fn raw_topic(name: &str) -> RawTopic {
    RawTopic {
        name: name.to_owned(),
        type_name: "rpkm_test_msgs/msg/Blob".to_owned(),
        definition: "uint8[] data\n".to_owned(),
        offered_qos_yaml: QosProfile::sensor_data().to_rosbag2_yaml(),
        type_hash: None,
    }
}

/// Writes `fast` messages of `/fast` and one `/late` message every [`LATE_EVERY`]; returns
/// (log time, topic, sequence) of every message in writing order.
fn write_bag(dir: &Path, options: BagWriterOptions, fast: u64) -> Vec<(u64, u8, u64)> {
    let mut bag = BagWriter::create(dir, options).expect("create");
    let topics = [
        bag.add_topic_raw(raw_topic("/fast")).expect("topic"),
        bag.add_topic_raw(raw_topic("/late")).expect("topic"),
    ];
    let t0 = 1_000_000_000_000u64;
    let mut written = Vec::new();
    let mut late = 0;
    for i in 0..fast {
        let t = t0 + i * PERIOD_NS;
        bag.write_raw(topics[0], t, t, &payload(0, i))
            .expect("write");
        written.push((t, 0, i));
        if i % LATE_EVERY == LATE_EVERY - 1 {
            let t = t - LATE_BY_NS;
            bag.write_raw(topics[1], t, t, &payload(1, late))
                .expect("write");
            written.push((t, 1, late));
            late += 1;
        }
    }
    let summary = bag.finish().expect("finish");
    assert!(summary.chunk_count > 50, "{} chunks", summary.chunk_count);
    written
}

#[test]
fn messages_come_in_log_time_order_holding_a_few_chunks() {
    let chunk_size = 64 * 1024;
    for compression in [
        BagCompression::None,
        BagCompression::Zstd,
        BagCompression::Lz4,
    ] {
        let tmp = tempfile::tempdir().expect("tempdir");
        let dir = tmp.path().join("bag");
        let options = BagWriterOptions {
            compression,
            chunk_size,
            ..Default::default()
        };
        let mut expected = write_bag(&dir, options, 7000);
        // the truth: every message written, stably sorted by log time (ties in writing order)
        expected.sort_by_key(|m| m.0);
        let payload_bytes = (expected.len() * PAYLOAD) as u64;
        assert!(payload_bytes >= 100 * chunk_size, "{payload_bytes}");

        let reader = BagReader::open(&dir).expect("open");
        assert_eq!(reader.message_count(), expected.len());
        let mut messages = reader.messages();
        let mut read = Vec::new();
        for (index, message) in messages.by_ref().enumerate() {
            let message = message.expect("read");
            assert_eq!(message.index, index);
            let (topic, seq) = (message.data[4], message.data[5..13].to_vec());
            let seq = u64::from_le_bytes(seq.try_into().expect("8 bytes"));
            assert_eq!(message.data, payload(topic, seq), "{compression:?} payload");
            let name = ["/fast", "/late"][usize::from(topic)];
            assert_eq!(message.topic, name);
            assert_eq!(reader.topics()[message.topic_index].name, name);
            assert_eq!(u64::from(message.sequence), seq);
            read.push((message.log_time, topic, seq));
        }
        assert_eq!(read, expected, "{compression:?}: log-time order");
        let peak = messages.peak_buffered_bytes();
        eprintln!("{compression:?}: {payload_bytes} payload bytes, peak {peak} buffered");
        // a chunk (closed just past chunk_size) plus the one overlapping it in time
        assert!(
            peak >= chunk_size && peak <= 3 * chunk_size,
            "{compression:?}: peak {peak} bytes buffered, chunks of {chunk_size}, \
             {payload_bytes} bytes of payload"
        );
    }
}

/// A bag changed after `open` checked it is reported while iterating, naming the file and
/// the chunk's byte offset, and iteration stops there.
#[test]
fn a_chunk_changed_after_open_is_an_error_naming_file_and_offset() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("bag");
    let options = BagWriterOptions {
        chunk_size: 16 * 1024,
        ..Default::default()
    };
    write_bag(&dir, options, 1000);
    let file = dir.join("bag_0.mcap");
    let reader = BagReader::open(&dir).expect("open");
    let mut bytes = std::fs::read(&file).expect("read");
    let flipped = bytes.len() / 2;
    bytes[flipped] ^= 0x10;
    std::fs::write(&file, &bytes).expect("write");
    let mut errors = Vec::new();
    let mut ok = 0;
    for message in reader.messages() {
        match message {
            Ok(_) => ok += 1,
            Err(err) => errors.push(err),
        }
    }
    assert_eq!(errors.len(), 1, "iteration stops at the first error");
    assert!(
        ok > 0 && ok < reader.message_count(),
        "{ok} messages before it"
    );
    match &errors[0] {
        BagReadError::Corrupt { path, offset, .. } | BagReadError::Changed { path, offset, .. } => {
            assert_eq!(path, &file);
            // the chunk holding the flipped byte starts before it, within a chunk's length
            assert!(*offset < flipped as u64 && flipped as u64 - offset < 20 * 1024);
            assert!(errors[0].to_string().contains(&format!("at byte {offset}")));
        }
        other @ BagReadError::Io { .. } => panic!("unexpected error {other}"),
    }
}

/// Set by the parent for the child run of `child_reads_the_bag`.
const CHILD_BAG_ENV: &str = "RPKM_BAG_STREAMING_CHILD";

/// The real process: a child reads and checks a bag of 48 MB (96 chunks) and reports its peak
/// resident memory (VmHWM), which a reader holding the bag would take above the bag's size.
#[test]
fn a_process_reading_a_large_bag_stays_far_below_its_size() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("large");
    let options = BagWriterOptions {
        chunk_size: 512 * 1024,
        ..Default::default()
    };
    let written = write_bag(&dir, options, 44_000);
    let bag_bytes = std::fs::metadata(dir.join("large_0.mcap"))
        .expect("bag")
        .len();
    let output = Command::new(std::env::current_exe().expect("test binary"))
        .args(["child_reads_the_bag", "--exact", "--ignored", "--nocapture"])
        .env(CHILD_BAG_ENV, &dir)
        .output()
        .expect("run the child");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let field = |key: &str| -> u64 {
        let line = stdout
            .lines()
            .find_map(|l| l.strip_prefix(key))
            .unwrap_or_else(|| panic!("no {key} in {stdout}"));
        line.trim().parse().expect("a number")
    };
    assert_eq!(field("messages:"), written.len() as u64);
    let hwm = field("vm_hwm_bytes:");
    eprintln!("bag of {bag_bytes} bytes read with a peak resident {hwm} bytes");
    assert!(
        hwm < bag_bytes / 3,
        "peak resident {hwm} bytes reading a bag of {bag_bytes} bytes"
    );
}

/// The child of `a_process_reading_a_large_bag_stays_far_below_its_size`: reads every message
/// of the bag it is given and prints the count and its peak resident memory.
#[test]
#[ignore = "run by a_process_reading_a_large_bag_stays_far_below_its_size"]
fn child_reads_the_bag() {
    let dir = PathBuf::from(std::env::var_os(CHILD_BAG_ENV).expect("run by the parent test"));
    let reader = BagReader::open(&dir).expect("open");
    let mut count = 0u64;
    let mut last = 0;
    for message in reader.messages() {
        let message = message.expect("read");
        assert!(message.log_time >= last);
        assert_eq!(message.data.len(), PAYLOAD);
        last = message.log_time;
        count += 1;
    }
    let status = std::fs::read_to_string("/proc/self/status").expect("/proc/self/status");
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM in /proc/self/status");
    println!("messages: {count}");
    println!("vm_hwm_bytes: {}", kib * 1024);
}
