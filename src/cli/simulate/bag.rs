//! `rpkm simulate --out BAG`: the twin's campaigns and actuator streams as a rosbag2 bag.

use std::path::{Path, PathBuf};

use anyhow::Result;
use rpkm_core::campaign::Campaign;
use rpkm_msgs::CampaignInfo;
use rpkm_transport::bag::BagWriter;
use rpkm_twin::Twin;

use super::args::SimulateArgs;
use crate::cli::bag_files::{bag_options, write_campaign_bag};
use rpkm_nodes::campaign_bag::{campaign_messages, stamp_ns, write_campaign, CampaignTopics};
use rpkm_nodes::stream::{self, StreamSpec};

/// Seconds between the end of the campaign (or the twin's start) and the stream.
const STREAM_GAP_S: f64 = 1.0;

/// `dir/name` → `dir/name_val`.
fn validation_bag(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map_or_else(|| "campaign".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{name}_val"))
}

pub fn run(args: &SimulateArgs, twin: &mut Twin, names: &[&str]) -> Result<()> {
    let (campaign, validation) = campaigns(args, twin, names)?;
    let spec = stream_spec(args, twin, campaign.as_ref())?;
    let messages = match &campaign {
        Some(c) => Some(campaign_messages(c).map_err(|e| crate::cli::bad_input(e.to_string()))?),
        None => None,
    };

    let mut bag = BagWriter::create(&args.out, bag_options(args.zstd))?;
    let topics = CampaignTopics::add(&mut bag)?;
    let mut count = 0;
    if args.record_parameters {
        count += write_parameters(&mut bag, twin)?;
    }
    if let Some(m) = &messages {
        count += write_campaign(&mut bag, &topics, m)?;
    } else {
        // A stream alone still names its covariate, and says where it comes from.
        let info = CampaignInfo {
            source: "rpkm simulate (actuator stream)".into(),
            comments: vec![format!(
                "rpkm digital twin: seed {}, effects [{}]",
                args.seed,
                args.effect.join(", ")
            )],
            covariate_names: vec!["temp_machine".into()],
        };
        let t0 = spec.map_or(0, |s| {
            rpkm_nodes::campaign_bag::stamp_from_seconds(s.start_s)
                .map_or(0, |t| u64::try_from(stamp_ns(t)).unwrap_or(0))
        });
        bag.write(&topics.info, t0, &info)?;
        count += 1;
    }
    let mut samples = 0;
    if let Some(spec) = &spec {
        samples = stream::run(twin, spec, |_, state| {
            let t = u64::try_from(stamp_ns(state.stamp)).unwrap_or(0);
            bag.write(&topics.state, t, state)?;
            Ok(())
        })?;
        count += samples;
    }
    let summary = bag.finish()?;
    let poses = campaign.as_ref().map_or(0, |c| c.poses.len());
    eprintln!(
        "{}: {poses} poses, {samples} stream samples, {count} messages in {} chunks",
        summary.dir.display(),
        summary.chunk_count
    );
    if let Some(v) = &validation {
        let path = validation_bag(&args.out);
        write_campaign_bag(v, &path, args.zstd)?;
        eprintln!("{}: {} validation poses", path.display(), v.poses.len());
    }
    if let Some(path) = &args.truth {
        let mut truth = serde_json::to_value(twin.truth())?;
        if let (Some(spec), Some(obj)) = (&spec, truth.as_object_mut()) {
            obj.insert("stream".into(), serde_json::to_value(spec)?);
        }
        crate::cli::write_json(path, &truth)?;
    }
    Ok(())
}

/// The twin's true parameters on /rpkm/parameters at its clock's start (before the campaign
/// and the stream), as a calibrator that found them exactly publishes them.
fn write_parameters(bag: &mut BagWriter, twin: &Twin) -> Result<u64> {
    let handle = rpkm_nodes::topics::add_bag_topic(bag, &rpkm_transport::topic::PARAMETERS)?;
    let model = rpkm_core::params::Model::M29;
    let sigmas = [0.0; rpkm_core::params::N_PARAMS];
    let msg = rpkm_msgs::Parameters {
        // no calibration's statistics: none was made
        cal_rms: f64::NAN,
        val_rms: f64::NAN,
        max_abs_residual: f64::NAN,
        condition_number: f64::NAN,
        ..rpkm_nodes::node::geometry::parameters_msg(twin.true_params(), model, &sigmas)
    };
    let t = rpkm_nodes::campaign_bag::stamp_from_seconds(twin.time())
        .map_or(0, |t| u64::try_from(stamp_ns(t)).unwrap_or(0));
    bag.write(&handle, t, &msg)?;
    Ok(1)
}

/// The main campaign `names` asks for (or the validation alone), and the validation poses
/// measured after it.
fn campaigns(
    args: &SimulateArgs,
    twin: &mut Twin,
    names: &[&str],
) -> Result<(Option<Campaign>, Option<Campaign>)> {
    let only_validation = !names.is_empty() && names.iter().all(|n| *n == "validation");
    let campaign: Option<Campaign> = if names.is_empty() {
        None
    } else if only_validation {
        let mut c = twin.validation(args.validation.max(1))?;
        c.source = args.out.display().to_string();
        Some(c)
    } else {
        let main: Vec<&str> = names
            .iter()
            .copied()
            .filter(|n| *n != "validation")
            .collect();
        Some(twin.campaign_by_names(&main, 0)?)
    };
    // Validation poses are measured after the main campaign, before the stream: the twin's
    // clock runs on, as in the CSV path.
    let validation = match (&campaign, only_validation, args.validation) {
        (Some(_), false, n) if n > 0 => Some(twin.validation(n)?),
        _ => None,
    };
    Ok((campaign, validation))
}

/// The actuator stream `--stream-hz` asks for, after the campaign.
fn stream_spec(
    args: &SimulateArgs,
    twin: &Twin,
    campaign: Option<&Campaign>,
) -> Result<Option<StreamSpec>> {
    Ok(match args.stream_hz {
        Some(hz) => Some(StreamSpec {
            hz,
            seconds: args.stream_seconds,
            motion: args.stream_motion,
            fault: args.fault,
            start_s: twin.time() + STREAM_GAP_S,
            first_seq: campaign.map_or(0, |c| c.poses.len() as u64),
        }),
        None if args.fault.is_some() => {
            return Err(crate::cli::bad_input(
                "--fault acts on the stream: give --stream-hz too".into(),
            ))
        }
        None => None,
    })
}
