//! Writes an 8 kHz stream of ActuatorState-like messages into a bag, in real time, until killed
//! (or for the given number of seconds). Used by `tests/bag_recover.rs` to test recovery after
//! SIGKILL.
//!
//! ```text
//! cargo run -p rpkm-transport --example bag_stress_writer -- <bag dir> [chunk bytes] [seconds]
//! ```
//!
//! Prints `flushed <n>` whenever the count of messages in flushed chunks grows: a lower bound of
//! what recovery must return after a kill.

#[path = "../tests/bag_common/mod.rs"]
mod bag_common;

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Context;
use rpkm_transport::bag::{BagWriter, BagWriterOptions, QosProfile};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = args
        .next()
        .context("usage: bag_stress_writer <bag dir> [chunk bytes] [seconds]")?;
    let chunk_size: u64 = args
        .next()
        .map_or(Ok(4096), |a| a.parse())
        .context("chunk bytes")?;
    let seconds: f64 = args
        .next()
        .map_or(Ok(60.0), |a| a.parse())
        .context("seconds")?;

    let options = BagWriterOptions {
        chunk_size,
        ..Default::default()
    };
    let mut bag = BagWriter::create(&dir, options).context("create bag")?;
    let topic = bag
        .add_topic::<bag_common::DriveSample>("/actuators/state", &QosProfile::sensor_data())
        .context("add topic")?;
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "started")?;
    stdout.flush()?;

    let period = Duration::from_micros(125);
    let start = Instant::now();
    let mut flushed = 0;
    for i in 0u64.. {
        let due = period * u32::try_from(i).context("too many messages")?;
        if due.as_secs_f64() > seconds {
            break;
        }
        if let Some(wait) = due.checked_sub(start.elapsed()) {
            std::thread::sleep(wait);
        }
        let (stamp, sample) = bag_common::drive_sample(i);
        bag.write(&topic, stamp, &sample).context("write")?;
        if bag.flushed_message_count() != flushed {
            flushed = bag.flushed_message_count();
            writeln!(stdout, "flushed {flushed}")?;
            stdout.flush()?;
        }
    }
    let summary = bag.finish().context("finish")?;
    writeln!(stdout, "finished {}", summary.message_count)?;
    Ok(())
}
