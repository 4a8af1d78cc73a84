//! `rpkm ingest CAMPAIGN.csv --out BAG`: a campaign file as a bag of ROS messages.

use std::path::PathBuf;

use super::bag_files::write_campaign_bag;
use anyhow::Result;

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
