//! `rpkm record`: subscribe to rpkm topics and write what arrives into a rosbag2 MCAP bag.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use super::transport_args::{stop_flag, TransportArgs};
use anyhow::Result;
use rpkm_transport::bag::{BagWriter, BagWriterOptions};

use rpkm_nodes::topics::{self, RecordPort};

/// Record rpkm topics into a rosbag2 folder (metadata.yaml + one .mcap; profile ros2, CDR,
/// schemas with their dependencies), readable by `ros2 bag`, Foxglove, mcap_ros2 and rosbags.
///
/// Each message is logged with its receive time. The file is written in chunks; every full
/// chunk (and at least every --flush-every seconds, the open one) is handed to the operating
/// system, so a recorder killed with SIGKILL loses at most that much: `rpkm bag recover` gets
/// the rest back. SIGINT (Ctrl-C) or SIGTERM stop it cleanly: the queued samples are written,
/// then the summary and metadata.yaml.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Examples:\n  rpkm record                                  # every rpkm topic, \
until Ctrl-C, into rpkm_YYYY_MM_DD-HH_MM_SS\n  rpkm record --out run1\n  rpkm record --out drives --topics /rpkm/actuator_state --duration 10\n  \
rpkm record --out run2 --backend dds          # what ROS 2 tools publish\n\n\
Topics: /rpkm/campaign_info, /rpkm/actuator_state, /rpkm/tcp_measurement, \
/rpkm/tcp_estimate, /rpkm/parameters, /rpkm/diagnosis, /rpkm/preload_status, /diagnostics."
)]
pub struct RecordArgs {
    /// Output bag folder; must not exist; missing parent folders are created (default:
    /// rpkm_YYYY_MM_DD-HH_MM_SS, the UTC start time, as `ros2 bag record`, in --out-dir).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Folder of the default-named bag when --out is not given (a launch file's recorder).
    #[arg(long, default_value = ".", conflicts_with = "out")]
    pub out_dir: PathBuf,
    /// Comma-separated topics to record (default: every rpkm topic).
    #[arg(long, value_delimiter = ',')]
    pub topics: Vec<String>,
    #[command(flatten)]
    pub transport: TransportArgs,
    /// Stop after this many seconds (default: until SIGINT/SIGTERM).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Chunk size in KiB: a full chunk is written at once; a SIGKILL loses at most one.
    #[arg(long, default_value_t = 1024)]
    pub chunk_kib: u64,
    /// Also write the open chunk after this many seconds without a full one, so that slow
    /// topics are safe on disk too (0: only full chunks).
    #[arg(long, default_value_t = 1.0)]
    pub flush_every: f64,
    /// Print a line to stderr each time a chunk is written: `flushed N messages`.
    #[arg(long)]
    pub progress: bool,
}

/// Samples taken from one subscriber before the next gets its turn: fair between topics.
const BATCH: usize = 256;
/// Sleep when a sweep over all subscribers found nothing: at 8 kHz about one sample waits per
/// sweep, far below the queue depth (64).
const IDLE_SLEEP: Duration = Duration::from_micros(100);

pub fn run(args: &RecordArgs) -> Result<()> {
    let names = checked_topics(args)?;
    let stop = stop_flag()?;
    let transport = args.transport.open("rpkm_record", "/rpkm/record")?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.out_dir.join(default_bag_name(SystemTime::now())));
    let mut bag = BagWriter::create(
        &out,
        BagWriterOptions {
            chunk_size: args.chunk_kib * 1024,
            ..BagWriterOptions::default()
        },
    )?;
    let mut ports: Vec<Box<dyn RecordPort>> = Vec::with_capacity(names.len());
    for name in &names {
        ports.push(topics::recorder(
            name,
            &transport,
            &mut bag,
            args.transport.delivery(),
        )?);
    }
    // Tests and scripts wait for this line before they start publishing.
    eprintln!(
        "rpkm record: recording {} topics to {}",
        ports.len(),
        out.display()
    );
    let start = Instant::now();
    record_until_stopped(args, &stop, &mut ports, &mut bag, start)?;
    // Write what is still queued, then close the bag.
    while ports
        .iter_mut()
        .map(|p| p.drain(&mut bag, BATCH))
        .sum::<Result<usize>>()?
        > 0
    {}
    let summary = bag.finish()?;
    let seconds = start.elapsed().as_secs_f64();
    eprintln!(
        "rpkm record: {} messages in {} chunks, {seconds:.3} s, into {}",
        summary.message_count,
        summary.chunk_count,
        summary.dir.display()
    );
    for port in &ports {
        eprintln!("  {}: {}", port.topic(), port.count());
    }
    Ok(())
}

/// `rpkm_YYYY_MM_DD-HH_MM_SS` of `now` in UTC: the bag name when `--out` is not given.
pub fn default_bag_name(now: SystemTime) -> String {
    let secs = now.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rest) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "rpkm_{y:04}_{m:02}_{d:02}-{:02}_{:02}_{:02}",
        rest / 3600,
        rest % 3600 / 60,
        rest % 60
    )
}

/// Gregorian (year, month, day) of a day count since 1970-01-01 (H. Hinnant's algorithm).
fn civil_from_days(days: u64) -> (u64, u64, u64) {
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + u64::from(m <= 2);
    (y, m, d)
}

/// The topics to record (all by default), and the flags checked.
fn checked_topics(args: &RecordArgs) -> Result<Vec<String>> {
    let names: Vec<String> = if args.topics.is_empty() {
        topics::ALL.iter().map(|s| (*s).to_owned()).collect()
    } else {
        args.topics.iter().map(|s| s.trim().to_owned()).collect()
    };
    topics::check_names(&names).map_err(|e| super::bad_input(e.to_string()))?;
    if args.chunk_kib == 0 {
        return Err(super::bad_input("--chunk-kib must be at least 1".into()));
    }
    if let Some(d) = args.duration {
        if !(d > 0.0 && d.is_finite()) {
            return Err(super::bad_input(format!(
                "--duration {d}: expected a positive number of seconds"
            )));
        }
    }
    Ok(names)
}

/// Takes samples from every port into the bag until SIGINT/SIGTERM or `--duration`, flushing
/// every `--flush-every` seconds.
fn record_until_stopped(
    args: &RecordArgs,
    stop: &AtomicBool,
    ports: &mut [Box<dyn RecordPort>],
    bag: &mut BagWriter,
    start: Instant,
) -> Result<()> {
    let deadline = args.duration.map(|d| start + Duration::from_secs_f64(d));
    let flush_every = (args.flush_every > 0.0).then(|| Duration::from_secs_f64(args.flush_every));
    let mut last_flush = Instant::now();
    let mut flushed = 0;
    loop {
        if stop.load(Ordering::Relaxed) || deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        let mut taken = 0;
        for port in ports.iter_mut() {
            taken += port.drain(bag, BATCH)?;
        }
        if flush_every.is_some_and(|every| last_flush.elapsed() >= every)
            && bag.message_count() > bag.flushed_message_count()
        {
            bag.flush()?;
        }
        if bag.flushed_message_count() != flushed {
            flushed = bag.flushed_message_count();
            last_flush = Instant::now();
            if args.progress {
                eprintln!("rpkm record: flushed {flushed} messages");
            }
        }
        if taken == 0 {
            std::thread::sleep(IDLE_SLEEP);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_bag_name_is_the_utc_start_time() {
        // 2024-02-29 23:59:59 UTC, a leap day; and the epoch.
        let t = UNIX_EPOCH + Duration::from_secs(1_709_251_199);
        assert_eq!(default_bag_name(t), "rpkm_2024_02_29-23_59_59");
        assert_eq!(default_bag_name(UNIX_EPOCH), "rpkm_1970_01_01-00_00_00");
        // 2000-03-01 00:00:00 UTC: after the 400-year leap day.
        let t = UNIX_EPOCH + Duration::from_secs(951_868_800);
        assert_eq!(default_bag_name(t), "rpkm_2000_03_01-00_00_00");
    }
}
