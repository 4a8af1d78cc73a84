//! Test-only messages and helpers shared by the `bag_*` integration tests.
#![expect(
    clippy::cast_possible_truncation,
    clippy::cast_possible_wrap,
    reason = "test and benchmark fixtures: counters, stamps and sizes far inside the target type's range"
)]
#![allow(dead_code)] // each test file uses a different part of this module

use rpkm_msgs::RosMessage;
use serde::{Deserialize, Serialize};

/// 80 `=` then `MSG: <name>`, rosbag2's separator of dependency definitions.
pub fn dependency(name: &str, text: &str) -> String {
    format!("{}\nMSG: {name}\n{text}", "=".repeat(80))
}

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Stamp {
    pub sec: i32,
    pub nanosec: u32,
}

pub const TIME_MSG: &str = "int32 sec\nuint32 nanosec\n";

impl Stamp {
    pub fn from_ns(ns: u64) -> Self {
        Self {
            sec: (ns / 1_000_000_000) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// An ActuatorState-like message: time stamp, fixed array, string, sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriveSample {
    pub stamp: Stamp,
    pub seq: u64,
    pub position: [f64; 4],
    pub label: String,
    pub force: Vec<f64>,
}

impl RosMessage for DriveSample {
    const PACKAGE: &'static str = "rpkm_test_msgs";
    const NAME: &'static str = "DriveSample";
    fn definition() -> String {
        format!(
            "builtin_interfaces/Time stamp\nuint64 seq\nfloat64[4] position\nstring label\n\
             float64[] force\n{}",
            dependency("builtin_interfaces/Time", TIME_MSG)
        )
    }
}

/// A second type with other primitive widths and a nested sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    pub stamp: Stamp,
    pub level: u8,
    pub code: i16,
    pub ok: bool,
    pub gain: f32,
    pub samples: Vec<Stamp>,
    pub text: String,
}

impl RosMessage for Event {
    const PACKAGE: &'static str = "rpkm_test_msgs";
    const NAME: &'static str = "Event";
    fn definition() -> String {
        format!(
            "builtin_interfaces/Time stamp\nuint8 level\nint16 code\nbool ok\nfloat32 gain\n\
             builtin_interfaces/Time[] samples\nstring text\n{}",
            dependency("builtin_interfaces/Time", TIME_MSG)
        )
    }
}

/// The generator of the stress writer and of the tests: sample `i` of an 8 kHz stream.
pub fn drive_sample(i: u64) -> (u64, DriveSample) {
    let t0 = 1_700_000_000_000_000_000u64;
    let stamp_ns = t0 + i * 125_000;
    let x = i as f64;
    let sample = DriveSample {
        stamp: Stamp::from_ns(stamp_ns),
        seq: i,
        position: [x * 1e-3, -x * 2e-3, x / 3.0, 0.1 + x * 1e-9],
        label: format!("s{}", i % 97),
        force: (0..(i % 5)).map(|k| x + k as f64 * 0.5).collect(),
    };
    (stamp_ns, sample)
}

pub fn event(i: u64) -> (u64, Event) {
    let t0 = 1_700_000_000_000_000_000u64;
    let stamp_ns = t0 + i * 1_000_000 + 7;
    (
        stamp_ns,
        Event {
            stamp: Stamp::from_ns(stamp_ns),
            level: (i % 3) as u8,
            code: -(i as i16) * 3,
            ok: i.is_multiple_of(2),
            gain: 0.5 + i as f32 * 0.25,
            samples: (0..(i % 4) as u32)
                .map(|k| Stamp {
                    sec: k as i32,
                    nanosec: k * 10,
                })
                .collect(),
            text: format!("event {i} – ünïcode"),
        },
    )
}
