//! `rpkm bag info|recover|campaign`: look into a bag, rescue a killed recording, get the
//! campaign CSV back.

use std::path::{Path, PathBuf};

use super::bag_files::open;
use anyhow::{Context, Result};
use rpkm_transport::bag::{recover, StopReason};

/// Inspect and repair rosbag2 MCAP bags (folders with metadata.yaml and one .mcap file).
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = "Examples:\n  rpkm bag info bags/stream_8khz\n  \
rpkm bag recover run1 --out run1_recovered   # a recorder was killed\n  \
rpkm bag campaign bags/calibration --out calibration.csv")]
pub struct BagArgs {
    #[command(subcommand)]
    pub command: BagCommand,
}

#[derive(clap::Subcommand, Debug, Clone)]
pub enum BagCommand {
    /// Topics, types, message counts, rates and duration of a bag (read from its files, not
    /// only from metadata.yaml).
    Info {
        /// Bag folder or bare .mcap file.
        bag: PathBuf,
    },
    /// Copy every complete chunk of a bag whose recorder was killed (SIGKILL, power loss)
    /// into a new, valid bag, and say how much was lost (the chunk that was open). The source
    /// is only read. A finished bag is copied whole.
    Recover {
        /// Bag folder (with or without metadata.yaml) or bare .mcap file.
        bag: PathBuf,
        /// The new bag folder; must not exist. Default: BAG_recovered next to BAG.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Rebuild the campaign CSV from a bag's /rpkm/campaign_info, /rpkm/actuator_state and
    /// /rpkm/tcp_measurement (as `rpkm ingest` or `rpkm simulate --out BAG` wrote them, or as
    /// recorded live): each TcpMeasurement with the ActuatorState before it is one pose.
    Campaign {
        /// Bag folder or bare .mcap file.
        bag: PathBuf,
        /// Output campaign CSV.
        #[arg(long)]
        out: PathBuf,
    },
}

pub fn run(args: &BagArgs) -> Result<()> {
    match &args.command {
        BagCommand::Info { bag } => info(bag),
        BagCommand::Recover { bag, out } => recover_cmd(bag, out.as_deref()),
        BagCommand::Campaign { bag, out } => campaign(bag, out),
    }
}

fn info(path: &Path) -> Result<()> {
    let bag = open(path)?;
    println!("bag:       {}", path.display());
    for file in bag.files() {
        let size = std::fs::metadata(file).map_or(0, |m| m.len());
        println!("file:      {} ({})", file.display(), human_bytes(size));
    }
    let (start, end) = bag.time_bounds().unwrap_or((0, 0));
    let duration_s = (end - start) as f64 * 1e-9;
    println!("messages:  {}", bag.message_count());
    println!("duration:  {duration_s:.6} s");
    println!(
        "start:     {:.9} s ({start} ns since the epoch)",
        start as f64 * 1e-9
    );
    println!("end:       {:.9} s", end as f64 * 1e-9);
    println!("topics:");
    let width = bag.topics().iter().map(|t| t.name.len()).max().unwrap_or(0);
    for t in bag.topics() {
        // Intervals over the bag's span: exact for a steady stream that fills the bag.
        let rate = if duration_s > 0.0 && t.message_count > 1 {
            format!("{:.1} Hz", (t.message_count - 1) as f64 / duration_s)
        } else {
            "-".to_owned()
        };
        println!(
            "  {:width$}  {:9} msgs  {:>10}  {}",
            t.name, t.message_count, rate, t.type_name
        );
    }
    Ok(())
}

fn human_bytes(n: u64) -> String {
    match n {
        n if n >= 1 << 20 => format!("{:.2} MiB", n as f64 / (1u64 << 20) as f64),
        n if n >= 1 << 10 => format!("{:.1} KiB", n as f64 / 1024.0),
        n => format!("{n} B"),
    }
}

/// `run1` → `run1_recovered`.
fn default_recovered(src: &Path) -> PathBuf {
    let name = src
        .file_stem()
        .map_or_else(|| "bag".into(), |s| s.to_string_lossy().into_owned());
    src.with_file_name(format!("{name}_recovered"))
}

fn recover_cmd(src: &Path, out: Option<&Path>) -> Result<()> {
    let dst = out.map_or_else(|| default_recovered(src), Path::to_path_buf);
    let report = recover(src, &dst).map_err(|e| match e {
        rpkm_transport::bag::RecoverError::Io { .. }
        | rpkm_transport::bag::RecoverError::Write(_) => anyhow::Error::new(e),
        other => super::bad_input(other.to_string()),
    })?;
    for f in &report.files {
        let stop = match &f.stop {
            StopReason::Complete => "complete: the writer had finished, nothing lost".to_owned(),
            StopReason::EndOfFile => "ends after its last complete chunk: the writer was \
                 killed; the messages of the chunk it still held in memory are lost (not \
                 countable from the file)"
                .to_owned(),
            StopReason::TruncatedRecord { offset, missing } => format!(
                "the record at byte {offset} is cut short ({missing} bytes missing): the chunk \
                 being written was lost"
            ),
            StopReason::CorruptRecord { offset, error } => {
                format!("unreadable record at byte {offset}: {error}")
            }
        };
        println!(
            "{}: {} of {} bytes recovered, {} lost; {} chunks, {} messages; {stop}",
            f.path.display(),
            f.valid_bytes,
            f.file_bytes,
            f.lost_bytes,
            f.chunks,
            f.messages
        );
    }
    let chunks: u64 = report.files.iter().map(|f| f.chunks).sum();
    println!(
        "recovered {} messages in {chunks} chunks into {}; lost {} bytes of unfinished records \
         in the file",
        report.messages_recovered,
        report.destination.display(),
        report.bytes_lost
    );
    for (topic, count) in &report.topics {
        println!("  {topic}: {count}");
    }
    Ok(())
}

fn campaign(path: &Path, out: &Path) -> Result<()> {
    let bag = open(path)?;
    let c = rpkm_nodes::campaign_bag::read_campaign(&bag)
        .map_err(|e| super::bad_input(format!("{}: {e:#}", path.display())))?;
    std::fs::write(out, c.to_csv()).with_context(|| format!("writing {}", out.display()))?;
    eprintln!(
        "{}: {} poses in {} setups",
        out.display(),
        c.poses.len(),
        c.setups().len()
    );
    Ok(())
}
