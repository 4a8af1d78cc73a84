//! `rpkm demo`: the story on the embedded default data (bags/demo, made by the twin with a
//! hidden effect): the thesis's simple model against the measurements, where it fails, the
//! test that says something is missing, the effect added, the held-out error falling.

use super::summary::{print_summary, um, write_report};
use anyhow::Context;
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::{self, DiagnosisOptions};
use rpkm_core::effects;
use rpkm_core::units::um_from_mm;
use std::path::PathBuf;

/// The embedded campaign: laser tracker + self-calibration on the twin, with a hidden
/// imperfect parallel-holder (see bags/README.md for the command that made it).
const CAMPAIGN: &str = include_str!("../../bags/demo/campaign.csv");
const VALIDATION: &str = include_str!("../../bags/demo/campaign.val.csv");

/// Run the demonstration on the embedded data and write an HTML report.
///
/// Example:
///   rpkm demo --out rpkm-demo && xdg-open rpkm-demo/report.html
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Folder for the report: report.html (one self-contained page) and report.json.
    #[arg(long, default_value = "rpkm-demo")]
    pub out: PathBuf,
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let campaign = Campaign::parse(CAMPAIGN, "bags/demo/campaign.csv")?;
    let val = Campaign::parse(VALIDATION, "bags/demo/campaign.val.csv")?;
    println!(
        "rpkm demo: {} poses (laser tracker + self-calibration) of a machine with a hidden \
         effect, {} held-out poses\n",
        campaign.poses.len(),
        val.poses.len()
    );
    let opts = DiagnosisOptions::default();
    let before = diagnose::diagnose(&campaign, Some(&val), &[], &opts)
        .context("diagnosing the embedded campaign")?;
    print_summary(&campaign, Some(&val), &before);
    let Some(missing) = before.missing_effect.clone() else {
        println!("\nnothing to add: the model explains the data");
        return Ok(());
    };
    println!("\n5. Adding {missing} to the model and diagnosing again");
    let effect = effects::by_name(&missing)?;
    let after = diagnose::diagnose(&campaign, Some(&val), &[effect.as_ref()], &opts)
        .context("diagnosing with the effect added")?;
    println!(
        "   chi2/dof at the stated noise {:.2} -> {:.2}; held-out RMS {} -> {} µm (noise floor {:.1} µm)",
        before.baseline.chi2_per_dof,
        after.baseline.chi2_per_dof,
        um(before.baseline.val_rms.map(um_from_mm)),
        um(after.baseline.val_rms.map(um_from_mm)),
        um_from_mm(after.baseline.noise_floor)
    );
    if let (Some(rms), Some(floor)) = (
        after.baseline.val_rms_relative.map(um_from_mm),
        after.baseline.noise_floor_relative.map(um_from_mm),
    ) {
        println!("   with each setup's zero removed: held-out RMS {rms:.1} µm, noise floor {floor:.1} µm");
    }
    println!("   verdict now: {}", rpkm_nodes::words::verdict(&after));
    let page = write_report(
        &args.out,
        "rpkm demo",
        (&campaign, Some(&val)),
        &before,
        Some(&after),
        (None, Vec::new()),
    )?;
    println!("\nreport: {}", page.display());
    Ok(())
}
