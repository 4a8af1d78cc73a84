//! `rpkm replay BAG`: publish a bag's rpkm topics through the transport.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::Result;
use rpkm_transport::bag::{BagReadError, BagReader};

use super::transport_args::{stop_flag, TransportArgs};
use rpkm_nodes::topics::{self, ReplayPort};

/// Publish the rpkm topics of a bag through the transport, in the bag's log-time order
/// (ties in file order), with the recorded timing scaled by --rate, or as fast as possible
/// (--rate max). Messages are published as recorded (stamps included), so the same bag gives
/// the same sequence on the topics every time.
///
/// Topics of the bag that rpkm does not know are skipped (and named on stderr).
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Examples:\n  rpkm replay bags/stream_8khz                 # real time\n  \
rpkm replay bags/calibration --rate 100       # 100 times faster\n  \
rpkm replay bags/stream_8khz --rate max --reliable   # lossless into `rpkm record --reliable`\n  \
rpkm replay run1 --topics /rpkm/actuator_state --backend dds"
)]
pub struct ReplayArgs {
    /// Bag folder or bare .mcap file (an unfinished one: `rpkm bag recover` first).
    pub bag: PathBuf,
    /// Speed: 1 is the recorded timing, N is N times faster (0.5: half speed), `max` is as
    /// fast as possible.
    #[arg(long, default_value = "1", value_parser = parse_rate)]
    pub rate: Rate,
    /// Comma-separated topics to publish (default: every rpkm topic of the bag).
    #[arg(long, value_delimiter = ',')]
    pub topics: Vec<String>,
    #[command(flatten)]
    pub transport: TransportArgs,
    /// Seconds to wait after creating the publishers before the first message, so that
    /// subscribers (and DDS discovery, about 0.2 s) can connect.
    #[arg(long, default_value_t = 0.0)]
    pub wait: f64,
}

/// Replay speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// Recorded time divided by this factor.
    Scaled(f64),
    /// No waiting.
    Max,
}

/// `max` or a positive factor.
pub fn parse_rate(s: &str) -> Result<Rate, String> {
    if s == "max" {
        return Ok(Rate::Max);
    }
    match s.parse::<f64>() {
        Ok(r) if r > 0.0 && r.is_finite() => Ok(Rate::Scaled(r)),
        _ => Err(format!(
            "{s:?}: expected a positive factor (1, 10, 0.5) or max"
        )),
    }
}

/// Sleep until this close to a message's due time, then spin: sleeps overshoot by 50-100 µs.
const SPIN_BEFORE: Duration = Duration::from_micros(300);

pub fn run(args: &ReplayArgs) -> Result<()> {
    if !(args.wait >= 0.0 && args.wait.is_finite()) {
        return Err(super::bad_input(format!(
            "--wait {}: expected seconds >= 0",
            args.wait
        )));
    }
    let bag = super::bag_files::open(&args.bag)?;
    let Selected {
        names: selected,
        port_of_topic,
        total,
    } = select_topics(args, &bag)?;
    let stop = stop_flag()?;
    let transport = args.transport.open("rpkm_replay", "/rpkm/replay")?;
    let mut ports: Vec<Box<dyn ReplayPort>> = Vec::with_capacity(selected.len());
    for name in &selected {
        ports.push(topics::publisher(
            name,
            &transport,
            args.transport.delivery(),
        )?);
    }
    eprintln!(
        "rpkm replay: {} messages on {} topics from {}",
        total,
        ports.len(),
        args.bag.display()
    );
    if args.wait > 0.0 {
        std::thread::sleep(Duration::from_secs_f64(args.wait));
    }
    let mut counts = vec![0u64; ports.len()];
    let mut t0: Option<u64> = None;
    let start = Instant::now();
    let mut last_history = start;
    // The bag is read as it goes, a chunk at a time (memory: a chunk, not the bag).
    for message in bag.messages() {
        let message = message.map_err(|e| match e {
            BagReadError::Io { .. } => anyhow::Error::new(e),
            other => super::bad_input(other.to_string()),
        })?;
        let Some(port) = port_of_topic.get(message.topic_index).copied().flatten() else {
            continue;
        };
        if stop.load(Ordering::Relaxed) {
            break;
        }
        if let Rate::Scaled(rate) = args.rate {
            let first = *t0.get_or_insert(message.log_time);
            let offset_ns = message.log_time.saturating_sub(first) as f64 / rate;
            let due = start + Duration::from_nanos(rpkm_core::convert::round_u64(offset_ns));
            wait_until(due);
        }
        ports[port].publish(&message.data).map_err(|e| {
            let what = format!(
                "{}: message {} (log time {} ns): {e}",
                args.bag.display(),
                message.index,
                message.log_time
            );
            // a payload that does not decode is the bag's fault (bad input, exit 2); a
            // transport that fails is this host's
            match e {
                topics::ReplayError::Decode { .. } => super::bad_input(what),
                topics::ReplayError::Transport(_) => anyhow::anyhow!(what),
            }
        })?;
        counts[port] += 1;
        deliver_history(&ports, &mut last_history)?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let published: u64 = counts.iter().sum();
    eprintln!(
        "rpkm replay: published {published} messages in {seconds:.3} s ({:.0} msg/s)",
        published as f64 / seconds.max(1e-9)
    );
    for (port, count) in ports.iter().zip(&counts) {
        eprintln!("  {}: {count}", port.topic());
    }
    Ok(())
}

/// How often the replay hands transient-local history to subscribers that joined late.
const HISTORY_EVERY: Duration = Duration::from_millis(100);

/// A subscriber that joined since the last look (a monitor started during the replay) gets
/// the bag's Parameters and CampaignInfo, as from the nodes that published them.
fn deliver_history(ports: &[Box<dyn topics::ReplayPort>], last: &mut Instant) -> Result<()> {
    if last.elapsed() < HISTORY_EVERY {
        return Ok(());
    }
    *last = Instant::now();
    for p in ports {
        p.deliver_history()
            .map_err(|e| anyhow::anyhow!("{}: {e}", p.topic()))?;
    }
    Ok(())
}

/// Sleeps, then spins, until `due`.
fn wait_until(due: Instant) {
    loop {
        let now = Instant::now();
        if now >= due {
            return;
        }
        let left = due - now;
        if left > SPIN_BEFORE {
            std::thread::sleep(left.saturating_sub(SPIN_BEFORE));
        } else {
            std::hint::spin_loop();
        }
    }
}

/// The bag's topics to publish.
struct Selected<'a> {
    names: Vec<&'a str>,
    /// Per topic of the bag its port, so that the timed loop neither hashes nor compares names.
    port_of_topic: Vec<Option<usize>>,
    /// Messages on the selected topics.
    total: u64,
}

/// The topics `--topics` names (all of rpkm's by default), each checked to be in the bag with
/// rpkm's type and CDR payloads.
fn select_topics<'a>(args: &ReplayArgs, bag: &'a BagReader) -> Result<Selected<'a>> {
    let wanted: Vec<String> = args.topics.iter().map(|s| s.trim().to_owned()).collect();
    topics::check_names(&wanted).map_err(|e| super::bad_input(e.to_string()))?;
    for name in &wanted {
        if bag.topic(name).is_none() {
            return Err(super::bad_input(format!(
                "{}: no topic {name} in the bag (it has {})",
                args.bag.display(),
                bag.topics()
                    .iter()
                    .map(|t| t.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    // Which bag topics to publish, after checking that their types are rpkm's.
    let mut selected: Vec<&str> = Vec::new();
    let mut port_of_topic: Vec<Option<usize>> = vec![None; bag.topics().len()];
    let mut total = 0;
    for (topic_index, t) in bag.topics().iter().enumerate() {
        let Some(expected) = topics::type_name(&t.name) else {
            eprintln!(
                "rpkm replay: skipping {} ({}): not an rpkm topic",
                t.name, t.type_name
            );
            continue;
        };
        if !wanted.is_empty() && !wanted.contains(&t.name) {
            continue;
        }
        if t.type_name != expected {
            return Err(super::bad_input(format!(
                "{}: topic {} has type {}, rpkm publishes {expected} there",
                args.bag.display(),
                t.name,
                t.type_name
            )));
        }
        // the payloads go out as they are: another encoding would reach subscribers as garbage
        if t.message_encoding != "cdr" {
            return Err(super::bad_input(format!(
                "{}: topic {} has message encoding {:?}, expected \"cdr\"",
                args.bag.display(),
                t.name,
                t.message_encoding
            )));
        }
        port_of_topic[topic_index] = Some(selected.len());
        total += t.message_count;
        selected.push(&t.name);
    }
    Ok(Selected {
        names: selected,
        port_of_topic,
        total,
    })
}
