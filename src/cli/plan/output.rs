//! What every plan writes: PLAN.csv and the JSON, and the words for the drives' mode.

use super::args::PlanArgs;
use anyhow::Context;
use rpkm_core::campaign::Instrument;
use rpkm_core::design::PlannedPose;
use rpkm_core::plan::{csv, CandidateSetup, DriveMode, DriveModeReason, Preload};

/// The drives' mode of a plan and its sentence.
pub struct Drives {
    pub mode: DriveMode,
    pub words: String,
}

/// PLAN.csv (`comments` after the drives' sentence) and the JSON (with the drives' mode),
/// where asked for.
pub fn write_outputs(
    args: &PlanArgs,
    (poses, drives): (&[PlannedPose], &Drives),
    comments: &[String],
    json: impl Fn() -> serde_json::Value,
) -> anyhow::Result<()> {
    if let Some(path) = &args.out {
        let mut all = vec![format!("drives: {}", drives.words)];
        all.extend(comments.iter().cloned());
        std::fs::write(path, csv::to_csv(poses, &all))
            .with_context(|| format!("writing {}", path.display()))?;
        println!("\nwrote {} ({} poses)", path.display(), poses.len());
    }
    if let Some(path) = &args.json {
        let mut j = json();
        j["drive_mode"] = serde_json::json!({
            "follower": rpkm_core::campaign::follower_text(drives.mode.follower),
            "reason": drives.mode.reason,
            "words": drives.words,
        });
        crate::cli::write_json(path, &j)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// "q2, q3 following", "all four drives active", "q1 following".
fn follower_words(follower: [bool; 4]) -> String {
    if follower == [false; 4] {
        return "all four drives active".to_owned();
    }
    let names: Vec<String> = (0..4)
        .filter(|&k| follower[k])
        .map(|k| format!("q{}", k + 1))
        .collect();
    format!("{} following", names.join(", "))
}

/// The drives' mode and why, in a sentence; with a warning where the poses will carry a
/// preload the model cannot represent (not modelled, all drives active).
pub fn mode_words(mode: &DriveMode, preload: Preload) -> String {
    let how = follower_words(mode.follower);
    let why = match mode.reason {
        DriveModeReason::Named => "as --follower names".to_owned(),
        DriveModeReason::PreloadModelled => {
            "the model carries preload_elastic and the campaign recorded the drive forces"
                .to_owned()
        }
        DriveModeReason::Campaign { rows, of } => {
            format!("as {rows} of the campaign's {of} external rows were measured")
        }
        DriveModeReason::NoPreload => {
            "the campaign has no external row, and the model no preload".to_owned()
        }
    };
    let mut s = format!("external instruments measure with {how} ({why})");
    if mode.all_active() && preload == Preload::NotModelled {
        s.push_str(
            "; the model carries no preload: measured so, the poses carry its deflection \
             (--effects preload_elastic with the drive forces recorded, or --follower 23 \
             where the cell can switch q2, q3 to followers)",
        );
    }
    s
}

/// How `--instruments` spells an instrument.
pub fn spelling(i: Instrument) -> &'static str {
    if i == Instrument::LiPsi {
        "psi"
    } else {
        i.as_str()
    }
}

/// "reset at (0, 1700), returns there" / "no reset".
pub fn setup_words(s: &CandidateSetup) -> String {
    match (s.reset, s.return_pose()) {
        (Some((x, y)), Some(_)) => format!("reset at ({x:.0}, {y:.0}), returns there"),
        (Some((x, y)), None) => format!("reset at ({x:.0}, {y:.0})"),
        (None, _) => "no reset".to_owned(),
    }
}

/// "plan_lt        lt      10 poses, reset at (0, 1700), returns there": a planned setup
/// on one line.
pub fn setup_line(s: &rpkm_core::plan::PlannedSetup) -> String {
    format!(
        "{:<14} {:<6} {:>3} poses, {}",
        s.setup.id,
        s.setup.instrument.as_str(),
        s.poses,
        setup_words(&s.setup)
    )
}
