//! A bag with every message type, read back by two independent Python readers
//! (`tests/python/bag_check.py`: `mcap_ros2` and `rosbags`), which must see exactly the values
//! written (floats bit for bit).
//!
//! Needs `/work/main/.venv` (or `RPKM_PYTHON`) with `mcap mcap-ros2-support rosbags`:
//! `python3 -m venv .venv && .venv/bin/pip install mcap mcap-ros2-support rosbags`.
//! Without it the test prints why and passes (CI creates the venv).

mod bag_common;

use std::path::PathBuf;
use std::process::Command;

use bag_common::{drive_sample, event, DriveSample, Event};
use rpkm_msgs::RosMessage;
use rpkm_transport::bag::{BagCompression, BagWriter, BagWriterOptions, QosProfile};
use serde_json::Value;

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn python() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("RPKM_PYTHON") {
        return Some(PathBuf::from(p));
    }
    let venv = repo_root().join(".venv/bin/python");
    // CI (.ci/run) installs the venv and sets RPKM_REQUIRE_PYTHON: there a skip is a failure.
    assert!(
        venv.is_file() || std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
        "RPKM_REQUIRE_PYTHON is set but {} is missing",
        venv.display()
    );
    venv.is_file().then_some(venv)
}

/// Replaces every scalar of a message's JSON form by a value derived from `seed` and the
/// leaf's position, so that no field is left at its default.
fn fill(value: &mut Value, seed: u64, counter: &mut u64) {
    *counter += 1;
    let k = seed * 31 + *counter;
    match value {
        Value::Bool(b) => *b = k % 2 == 1,
        Value::Number(n) => {
            *value = if n.is_f64() {
                Value::from((k as f64) / 3.0 - 7.25)
            } else {
                Value::from(k % 100)
            }
        }
        Value::String(s) => *s = format!("s{k} ä"),
        Value::Array(items) => items.iter_mut().for_each(|v| fill(v, seed, counter)),
        Value::Object(map) => map.values_mut().for_each(|v| fill(v, seed, counter)),
        Value::Null => {}
    }
}

fn filled<T: RosMessage + Default>(seed: u64) -> T {
    let mut json = serde_json::to_value(T::default()).expect("to json");
    fill(&mut json, seed, &mut 0);
    serde_json::from_value(json).expect("filled value fits the type")
}

struct Expected {
    topic: String,
    type_name: String,
    log_time: u64,
    value: Value,
}

fn add_all<T: RosMessage + Default>(
    bag: &mut BagWriter,
    expected: &mut Vec<Expected>,
    topic: &str,
    t0: u64,
) {
    let handle = bag
        .add_topic::<T>(topic, &QosProfile::default())
        .expect("add topic");
    for i in 0..3 {
        let value: T = filled(i + t0 % 1000);
        let log_time = t0 + i * 1000;
        bag.write(&handle, log_time, &value).expect("write");
        expected.push(Expected {
            topic: topic.to_owned(),
            type_name: T::type_name(),
            log_time,
            value: serde_json::to_value(&value).expect("json"),
        });
    }
}

fn normalise(mut messages: Vec<(String, String, u64, Value)>) -> Vec<(String, String, u64, Value)> {
    messages.sort_by(|a, b| (a.2, &a.0).cmp(&(b.2, &b.0)));
    messages
}

#[test]
#[expect(
    clippy::too_many_lines,
    reason = "an end-to-end scenario, read top to bottom"
)]
fn python_readers_see_the_values_written() {
    let Some(python) = python() else {
        println!("skipped: no .venv/bin/python (python3 -m venv .venv && .venv/bin/pip install mcap mcap-ros2-support rosbags)");
        return;
    };
    let script = repo_root().join("tests/python/bag_check.py");
    for compression in [BagCompression::None, BagCompression::Zstd] {
        let tmp = tempfile::tempdir().expect("tempdir");
        let dir = tmp.path().join("all_types");
        let mut bag = BagWriter::create(
            &dir,
            BagWriterOptions {
                compression,
                chunk_size: 2048,
                ..Default::default()
            },
        )
        .expect("create");
        let mut expected = Vec::new();
        let drives = bag
            .add_topic::<DriveSample>("/test/drives", &QosProfile::sensor_data())
            .expect("drives");
        let events = bag
            .add_topic::<Event>("/test/events", &QosProfile::default())
            .expect("events");
        for i in 0..50 {
            let (t, s) = drive_sample(i);
            bag.write(&drives, t, &s).expect("write");
            expected.push(Expected {
                topic: "/test/drives".into(),
                type_name: DriveSample::type_name(),
                log_time: t,
                value: serde_json::to_value(&s).expect("json"),
            });
            if i % 10 == 0 {
                let (t, e) = event(i);
                bag.write(&events, t, &e).expect("write");
                expected.push(Expected {
                    topic: "/test/events".into(),
                    type_name: Event::type_name(),
                    log_time: t,
                    value: serde_json::to_value(&e).expect("json"),
                });
            }
        }
        let t0 = 1_800_000_000_000_000_000;
        add_all::<rpkm_msgs::ActuatorState>(&mut bag, &mut expected, "/actuators/state", t0 + 1);
        add_all::<rpkm_msgs::TcpEstimate>(&mut bag, &mut expected, "/tcp/estimate", t0 + 2);
        add_all::<rpkm_msgs::TcpMeasurement>(&mut bag, &mut expected, "/tcp/measurement", t0 + 3);
        add_all::<rpkm_msgs::PreloadStatus>(&mut bag, &mut expected, "/preload/status", t0 + 4);
        add_all::<rpkm_msgs::Parameters>(&mut bag, &mut expected, "/parameters", t0 + 5);
        add_all::<rpkm_msgs::Diagnosis>(&mut bag, &mut expected, "/diagnosis", t0 + 6);
        add_all::<rpkm_msgs::DiagnosisCandidate>(&mut bag, &mut expected, "/candidate", t0 + 7);
        add_all::<rpkm_msgs::DiagnosticArray>(&mut bag, &mut expected, "/diagnostics", t0 + 8);
        add_all::<rpkm_msgs::DiagnosticStatus>(&mut bag, &mut expected, "/status", t0 + 9);
        add_all::<rpkm_msgs::KeyValue>(&mut bag, &mut expected, "/key_value", t0 + 10);
        add_all::<rpkm_msgs::Header>(&mut bag, &mut expected, "/header", t0 + 11);
        add_all::<rpkm_msgs::Time>(&mut bag, &mut expected, "/time", t0 + 12);
        add_all::<rpkm_msgs::CampaignInfo>(&mut bag, &mut expected, "/campaign_info", t0 + 13);
        bag.finish().expect("finish");

        let output = Command::new(&python)
            .arg(&script)
            .arg(&dir)
            .output()
            .expect("run bag_check.py");
        assert!(
            output.status.success(),
            "bag_check.py failed ({compression:?}):\n{}",
            String::from_utf8_lossy(&output.stderr)
        );
        let result: Value = serde_json::from_slice(&output.stdout).expect("JSON from bag_check.py");
        let want = normalise(
            expected
                .iter()
                .map(|e| {
                    (
                        e.topic.clone(),
                        e.type_name.clone(),
                        e.log_time,
                        e.value.clone(),
                    )
                })
                .collect(),
        );
        for reader in ["mcap_ros2", "rosbags"] {
            let got = normalise(
                result[reader]
                    .as_array()
                    .unwrap_or_else(|| panic!("{reader}: no message list"))
                    .iter()
                    .map(|m| {
                        (
                            m["topic"].as_str().unwrap_or_default().to_owned(),
                            m["type"].as_str().unwrap_or_default().to_owned(),
                            m["log_time"].as_u64().unwrap_or_default(),
                            m["value"].clone(),
                        )
                    })
                    .collect(),
            );
            assert_eq!(got.len(), want.len(), "{reader}: message count");
            for (g, w) in got.iter().zip(&want) {
                assert_eq!(g, w, "{reader} ({compression:?}) differs");
            }
        }
    }
}
