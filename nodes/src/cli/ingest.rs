//! `rpkm ingest CAMPAIGN.csv --out BAG`: a campaign file as a bag of ROS messages.

use std::path::{Path, PathBuf};

use anyhow::Result;
use rpkm_core::campaign::Campaign;
use rpkm_transport::bag::{BagCompression, BagWriter, BagWriterOptions};

use crate::campaign_bag::{campaign_messages, write_campaign, CampaignTopics};

/// Convert a campaign CSV (spec format, mm) into a rosbag2 MCAP bag of ROS messages (SI):
/// /rpkm/campaign_info (source, comments, covariate names), then per pose one
/// /rpkm/actuator_state (q in m, forces, followers, covariates; seq = pose index) and one
/// /rpkm/tcp_measurement (setup, instrument, reset, x/y/r in m, psi in rad), stamped and
/// logged at the pose's time t. `rpkm bag campaign BAG --out FILE.csv` gives the campaign back.
///
/// Example:
///   rpkm ingest bags/demo/campaign.csv --out demo_bag && rpkm bag info demo_bag
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Example:\n  rpkm ingest bags/demo/campaign.csv --out demo_bag\n  \
rpkm bag info demo_bag\n  rpkm bag campaign demo_bag --out again.csv   # the same campaign"
)]
pub struct IngestArgs {
    /// Campaign CSV (see the spec's "Campaign CSV"); t must be >= 0 (it becomes the log time).
    pub campaign: PathBuf,
    /// Output bag folder; must not exist.
    #[arg(long)]
    pub out: PathBuf,
    /// Compress chunks with zstd (smaller; every rosbag2/MCAP reader handles it).
    #[arg(long)]
    pub zstd: bool,
}

pub fn run(args: &IngestArgs) -> Result<()> {
    let c = super::read_campaign(&args.campaign)?;
    let count = write_campaign_bag(&c, &args.out, args.zstd)?;
    eprintln!(
        "{}: {} poses in {} setups, {count} messages",
        args.out.display(),
        c.poses.len(),
        c.setups().len()
    );
    Ok(())
}

/// Bag options of the commands that write campaigns: default chunks, optional zstd.
pub fn bag_options(zstd: bool) -> BagWriterOptions {
    BagWriterOptions {
        compression: if zstd {
            BagCompression::Zstd
        } else {
            BagCompression::None
        },
        ..BagWriterOptions::default()
    }
}

/// Writes campaign `c` as a new bag folder `out`; returns the number of messages. Nothing is
/// created for a campaign the messages cannot hold (bad input, exit code 2).
pub fn write_campaign_bag(c: &Campaign, out: &Path, zstd: bool) -> Result<u64> {
    let messages = campaign_messages(c).map_err(|e| super::bad_input(e.to_string()))?;
    let mut bag = BagWriter::create(out, bag_options(zstd))?;
    let topics = CampaignTopics::add(&mut bag)?;
    let count = write_campaign(&mut bag, &topics, &messages)?;
    bag.finish()?;
    Ok(count)
}
