//! Bags as the commands write and open them: the writer's options, a campaign written as a
//! bag (`rpkm ingest`, `rpkm simulate`), a bag opened with its errors as bad input (`rpkm bag`,
//! `rpkm replay`).

use anyhow::Result;
use rpkm_core::campaign::Campaign;
use rpkm_transport::bag::{BagCompression, BagOpenError, BagReader, BagWriter, BagWriterOptions};
use std::path::Path;

use rpkm_nodes::campaign_bag::{campaign_messages, write_campaign, CampaignTopics};

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

/// Opens a bag; a bad or unfinished bag is bad input (exit code 2).
pub fn open(path: &Path) -> Result<BagReader> {
    BagReader::open(path).map_err(|e| match e {
        BagOpenError::Io { .. } => anyhow::Error::new(e),
        BagOpenError::Truncated { .. } => super::bad_input(format!(
            "{e}\n  (run `rpkm bag recover {}`)",
            path.display()
        )),
        other => super::bad_input(other.to_string()),
    })
}
