//! `rpkm simulate`: measurement campaigns from the digital twin.

use anyhow::{bail, Context, Result};
use rpkm_core::twin::{EffectKind, Twin, TwinConfig};
use std::path::{Path, PathBuf};

/// Simulate measurement campaigns on the digital twin (a seeded true machine with hidden
/// effects) and write them in the campaign CSV format.
///
/// Example:
///   rpkm simulate --campaign lt,self --effect thermal=2,encoder_scale --seed 7 \
///       --out lt_self.csv --truth truth.json --validation 100
/// writes lt_self.csv, the held-out validation poses to lt_self.val.csv and the hidden truth
/// (true parameters, stiffness, effects) to truth.json.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Campaigns: lt, kgm, dbb, li_x, li_y, li_psi, self, circle, validation.\n\
Effects (default magnitude, unit): parallelogram (0.15 mm), preload_elastic (1, compliance \
factor), thermal (2 K), encoder_scale (40 ppm), guide_straightness (0.05 mm), \
instrument_alignment (0.05 mrad).\n\n\
Example:\n  rpkm simulate --campaign lt,self --effect thermal=2,encoder_scale --seed 7 \
--out lt_self.csv --truth truth.json --validation 100"
)]
pub struct SimulateArgs {
    /// Comma-separated campaigns, measured one after the other into one file.
    #[arg(long, value_delimiter = ',', required = true)]
    pub campaign: Vec<String>,
    /// Hidden effects, NAME or NAME=MAGNITUDE, comma-separated (default magnitude if none).
    #[arg(long, value_delimiter = ',')]
    pub effect: Vec<String>,
    /// Seed of the true machine, the noise and the validation poses.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output campaign CSV.
    #[arg(long)]
    pub out: PathBuf,
    /// Where to write the hidden truth as JSON.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Number of held-out validation poses, written to FILE.val.csv (0: none). With
    /// `--campaign validation` alone they go to --out.
    #[arg(long, default_value_t = 100)]
    pub validation: usize,
    /// Noise-free instruments and encoders.
    #[arg(long)]
    pub no_noise: bool,
}

/// Parse `NAME[=MAGNITUDE]`.
pub fn parse_effect(s: &str) -> Result<(EffectKind, f64)> {
    let (name, mag) = match s.split_once('=') {
        Some((n, m)) => (n, Some(m)),
        None => (s, None),
    };
    let kind: EffectKind = name
        .trim()
        .parse()
        .map_err(|e: rpkm_core::twin::UnknownEffect| super::bad_input(e.to_string()))?;
    let m = match mag {
        Some(m) => m.trim().parse::<f64>().map_err(|_| {
            super::bad_input(format!("magnitude of effect {name}: {m:?} is not a number"))
        })?,
        None => kind.default_magnitude(),
    };
    Ok((kind, m))
}

/// `dir/name.csv` → `dir/name.val.csv`.
fn validation_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "campaign".into());
    out.with_file_name(format!("{stem}.val.csv"))
}

pub fn run(args: &SimulateArgs) -> Result<()> {
    let effects = args
        .effect
        .iter()
        .filter(|s| !s.trim().is_empty())
        .map(|s| parse_effect(s))
        .collect::<Result<Vec<_>>>()?;
    let mut twin = Twin::new(TwinConfig {
        seed: args.seed,
        effects,
        noise: !args.no_noise,
        ..TwinConfig::default()
    })?;
    let names: Vec<&str> = args.campaign.iter().map(|s| s.trim()).collect();
    if names.is_empty() {
        bail!("--campaign needs at least one campaign");
    }
    let only_validation = names.iter().all(|n| *n == "validation");
    if only_validation {
        let mut c = twin.validation(args.validation.max(1))?;
        c.source = args.out.display().to_string();
        std::fs::write(&args.out, c.to_csv())
            .with_context(|| format!("writing {}", args.out.display()))?;
        eprintln!("{}: {} poses", args.out.display(), c.poses.len());
    } else {
        let main: Vec<&str> = names
            .iter()
            .copied()
            .filter(|n| *n != "validation")
            .collect();
        let c = twin.campaign_by_names(&main, 0)?;
        std::fs::write(&args.out, c.to_csv())
            .with_context(|| format!("writing {}", args.out.display()))?;
        eprintln!(
            "{}: {} poses in {} setups",
            args.out.display(),
            c.poses.len(),
            c.setups().len()
        );
        if args.validation > 0 {
            let v = twin.validation(args.validation)?;
            let path = validation_path(&args.out);
            std::fs::write(&path, v.to_csv())
                .with_context(|| format!("writing {}", path.display()))?;
            eprintln!("{}: {} validation poses", path.display(), v.poses.len());
        }
    }
    if let Some(path) = &args.truth {
        super::write_json(path, &serde_json::to_value(twin.truth())?)?;
    }
    Ok(())
}
