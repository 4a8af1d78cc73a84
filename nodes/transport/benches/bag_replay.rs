//! Replay speed: a bag of 200,000 ActuatorState messages read and decoded by `BagReader` and by
//! Python `mcap_ros2` (tests/python/bag_check.py --bench), on the same machine in the same run.
//!
//! `cargo bench -p rpkm-transport --bench bag_replay` (Python part skipped without `.venv`).
#![expect(
    clippy::cast_possible_truncation,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use rpkm_msgs::{ActuatorState, Time};
use rpkm_transport::bag::{BagReader, BagWriter, BagWriterOptions, QosProfile};

const MESSAGES: u64 = 200_000;

fn sample(i: u64) -> (u64, ActuatorState) {
    let stamp_ns = 1_700_000_000_000_000_000 + i * 125_000;
    let x = i as f64;
    let mut state = ActuatorState {
        stamp: Time {
            sec: (stamp_ns / 1_000_000_000) as i32,
            nanosec: (stamp_ns % 1_000_000_000) as u32,
        },
        seq: i,
        position: [x * 1e-6, -x * 2e-6, x * 3e-6, 0.5],
        force: [x, -x, 0.5 * x, 1.0],
        follower: [false, i.is_multiple_of(2), false, true],
        ..Default::default()
    };
    let _ = state.set_covariates(&[20.0 + x * 1e-4, 21.5]);
    (stamp_ns, state)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let tmp = tempfile::tempdir()?;
    let dir = tmp.path().join("replay");

    let start = Instant::now();
    let mut bag = BagWriter::create(&dir, BagWriterOptions::default())?;
    let topic = bag.add_topic::<ActuatorState>("/actuators/state", &QosProfile::sensor_data())?;
    for i in 0..MESSAGES {
        let (t, s) = sample(i);
        bag.write(&topic, t, &s)?;
    }
    let summary = bag.finish()?;
    let write_s = start.elapsed().as_secs_f64();
    let bytes = std::fs::metadata(&summary.mcap_path)?.len();

    // Best of three: open (read + index) and decode every message.
    let mut rust_s = f64::INFINITY;
    for _ in 0..3 {
        let start = Instant::now();
        let reader = BagReader::open(&dir)?;
        let mut checksum = 0.0;
        for message in reader.messages() {
            let state: ActuatorState = message?.decode()?;
            checksum += state.position[0];
        }
        let elapsed = start.elapsed().as_secs_f64();
        assert_eq!(reader.message_count() as u64, MESSAGES);
        std::hint::black_box(checksum);
        rust_s = rust_s.min(elapsed);
    }

    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let python = std::env::var_os("RPKM_PYTHON")
        .map_or_else(|| root.join(".venv/bin/python"), PathBuf::from);
    let python_s = if python.is_file() {
        let output = Command::new(&python)
            .arg(root.join("tests/python/bag_check.py"))
            .arg(&dir)
            .arg("--bench")
            .output()?;
        if !output.status.success() {
            return Err(format!(
                "bag_check.py --bench failed: {}",
                String::from_utf8_lossy(&output.stderr)
            )
            .into());
        }
        let report: serde_json::Value = serde_json::from_slice(&output.stdout)?;
        assert_eq!(report["messages"].as_u64(), Some(MESSAGES));
        report["seconds"].as_f64()
    } else {
        println!("python part skipped: {} not found", python.display());
        None
    };

    let rate = |s: f64| MESSAGES as f64 / s;
    println!(
        "bag: {MESSAGES} ActuatorState messages, {:.1} MiB, {} chunks, written in {:.3} s \
         ({:.0} msg/s)",
        bytes as f64 / (1024.0 * 1024.0),
        summary.chunk_count,
        write_s,
        rate(write_s)
    );
    println!("| reader (read + decode)      | seconds | messages/s |");
    println!("|-----------------------------|---------|------------|");
    println!(
        "| rpkm BagReader (best of 3)  | {rust_s:7.3} | {:10.0} |",
        rate(rust_s)
    );
    if let Some(py) = python_s {
        println!(
            "| Python mcap_ros2 (1 run)    | {py:7.3} | {:10.0} |",
            rate(py)
        );
        println!("ratio rust/python: {:.1}x", py / rust_s);
    }
    Ok(())
}
