//! Recovery of bags whose writer did not finish: files cut at every length, and a real writer
//! process killed with SIGKILL.

mod bag_common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use bag_common::{drive_sample, DriveSample};
use rpkm_transport::bag::{
    recover, BagOpenError, BagReader, BagWriter, BagWriterOptions, QosProfile, StopReason,
};

/// Checks that the bag at `dir` holds exactly samples `0..n` of the generator; returns `n`.
fn check_prefix(dir: &Path) -> u64 {
    let reader = BagReader::open(dir).expect("recovered bag opens");
    let mut n = 0u64;
    for message in reader.messages() {
        let message = message.expect("read");
        assert_eq!(message.topic, "/actuators/state");
        assert_eq!(
            u64::from(message.sequence),
            n,
            "sequence numbers contiguous from 0"
        );
        let (stamp, expected) = drive_sample(n);
        assert_eq!(message.log_time, stamp);
        let value: DriveSample = message.decode().expect("decodes");
        assert_eq!(value, expected, "message {n} matches the generator");
        n += 1;
    }
    let meta = reader.metadata().expect("fresh metadata.yaml");
    assert_eq!(meta.message_count, n);
    n
}

#[test]
fn every_cut_of_a_file_recovers_a_prefix() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("full");
    let mut bag = BagWriter::create(
        &dir,
        BagWriterOptions {
            chunk_size: 1024,
            ..Default::default()
        },
    )
    .expect("create");
    let topic = bag
        .add_topic::<DriveSample>("/actuators/state", &QosProfile::sensor_data())
        .expect("topic");
    for i in 0..300 {
        let (t, s) = drive_sample(i);
        bag.write(&topic, t, &s).expect("write");
    }
    bag.finish().expect("finish");
    let bytes = std::fs::read(dir.join("full_0.mcap")).expect("read");

    let mut previous = 0;
    for (k, len) in (0..=bytes.len())
        .step_by(61)
        .chain([bytes.len()])
        .enumerate()
    {
        let cut = tmp.path().join(format!("cut{k}.mcap"));
        std::fs::write(&cut, &bytes[..len]).expect("write cut");
        let out = tmp.path().join(format!("rec{k}"));
        match recover(&cut, &out) {
            Ok(report) => {
                let n = check_prefix(&out);
                assert_eq!(report.messages_recovered, n);
                assert!(n >= previous, "a longer cut never recovers less");
                previous = n;
                let file = &report.files[0];
                if file.stop == StopReason::Complete {
                    // Cut inside the summary section, or not at all: every message is there.
                    assert_eq!((n, file.lost_bytes), (300, 0));
                } else {
                    assert_eq!(file.valid_bytes + file.lost_bytes, len as u64);
                }
                if len == bytes.len() {
                    assert_eq!(file.stop, StopReason::Complete);
                }
            }
            // Shorter than the magic: not an MCAP file at all.
            Err(err) => assert!(len < 8, "cut at {len}: {err}"),
        }
    }
}

/// Path of the `bag_stress_writer` example, built by `cargo test` next to the test binaries.
fn stress_writer() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let profile_dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>/deps");
    profile_dir
        .join("examples")
        .join(format!("bag_stress_writer{}", std::env::consts::EXE_SUFFIX))
}

#[test]
fn writer_killed_with_sigkill_is_recovered() {
    let exe = stress_writer();
    assert!(
        exe.is_file(),
        "{} missing: `cargo test -p rpkm-transport` builds it (with `--test bag_recover` alone, \
         first `cargo build -p rpkm-transport --example bag_stress_writer`)",
        exe.display()
    );
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("killed");
    let mut child = Command::new(&exe)
        .arg(&dir)
        .arg("4096")
        .arg("30")
        .stdout(Stdio::piped())
        .spawn()
        .expect("start the stress writer");
    let stdout = child.stdout.take().expect("piped stdout");
    let (tx, rx) = mpsc::channel();
    let lines = std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    // Let it run about a second after its first flushed chunk.
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut flushed = 0u64;
    let mut first_flush: Option<Instant> = None;
    while first_flush.is_none_or(|t| t.elapsed() < Duration::from_secs(1)) {
        let line = rx
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            .expect("the stress writer reports flushed chunks within 60 s");
        if let Some(n) = line.strip_prefix("flushed ") {
            flushed = n.parse().expect("count");
            first_flush.get_or_insert_with(Instant::now);
        }
    }
    child.kill().expect("SIGKILL");
    child.wait().expect("reap");
    lines.join().expect("reader thread");
    for line in rx.try_iter() {
        if let Some(n) = line.strip_prefix("flushed ") {
            flushed = n.parse().expect("count");
        }
    }

    assert!(
        !dir.join("metadata.yaml").exists(),
        "killed before finishing"
    );
    assert!(matches!(
        BagReader::open(&dir),
        Err(BagOpenError::Truncated { .. })
    ));
    let out = tmp.path().join("recovered");
    let report = recover(&dir, &out).expect("recover");
    let n = check_prefix(&out);
    println!(
        "flushed {flushed}, recovered {n} messages in {} chunks, {} bytes kept, {} lost ({:?})",
        report.files[0].chunks, report.bytes_recovered, report.bytes_lost, report.files[0].stop
    );
    assert_eq!(report.messages_recovered, n);
    assert!(
        n >= flushed,
        "recovered {n} < {flushed} flushed before the kill"
    );
    assert!(n > 1000, "about a second at 8 kHz, got {n}");
    assert!(matches!(
        report.files[0].stop,
        StopReason::EndOfFile | StopReason::TruncatedRecord { .. }
    ));
}
