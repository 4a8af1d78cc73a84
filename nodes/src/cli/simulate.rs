//! `rpkm simulate`: measurement campaigns from the digital twin.

use anyhow::{bail, Context, Result};
use rpkm_core::noise::NoiseModel;
use rpkm_core::twin::{EffectKind, Twin, TwinConfig};
use std::path::{Path, PathBuf};

/// Simulate measurement campaigns on the digital twin (a seeded true machine with hidden
/// effects) and write them in the campaign CSV format, or as a rosbag2 MCAP bag (--out not
/// ending in .csv) holding the same messages as `rpkm ingest` and, with --stream-hz, an
/// ActuatorState stream at the control rate.
///
/// Example:
///   rpkm simulate --campaign lt,self --effect thermal=2,encoder_scale --seed 7 \
///       --out lt_self.csv --truth truth.json --validation 100
/// writes lt_self.csv, the held-out validation poses to lt_self.val.csv and the hidden truth
/// (true parameters, stiffness, effects) to truth.json.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Campaigns: lt, kgm, dbb, li_x, li_y, li_psi, self, circle, validation, production (500 poses all drives active, no instrument: the drive forces are the measurements; with --effect preload_elastic).\n\
Effects (default magnitude, unit): parallelogram (2 mm), preload_elastic (0.3, scale of the \
controller's parameter error: all drives active), thermal (5 K), encoder_scale (40 ppm), \
guide_straightness (0.08 mm), instrument_alignment (0.05 mrad), backlash (0.03 mm, with \
approach_q1/approach_q4 covariates; not in the diagnosis library), lost_motion_q4 (0.01 mm, \
carrier 4 alone, nothing recorded beside it).\n\n\
A plan (rpkm plan --out plan.csv):\n  rpkm simulate --plan plan.csv --effect lost_motion_q4 --seed 7 --out planned.csv\n\n\
Example:\n  rpkm simulate --campaign lt,self --effect thermal=2,encoder_scale --seed 7 \
--out lt_self.csv --truth truth.json --validation 100\n\n\
Bags (--out not ending in .csv; validation poses go to the bag OUT_val):\n  \
rpkm simulate --campaign lt,self --effect parallelogram=1.0 --seed 7 --out calibration \
--validation 0\n  \
rpkm simulate --stream-hz 8000 --stream-seconds 0.5 --seed 3 --out stream_8khz\n  \
rpkm simulate --stream-hz 1000 --stream-seconds 2 --stream-motion hold --fault q3=0.8 \
--effect preload_elastic=1 --seed 5 --out preload_fault --truth preload_fault.truth.json\n\n\
Production stream (CSV, truth in prod.truth.csv):\n  \
rpkm simulate --production-seconds 600 --production-step l3=0.1@300 --production-decimate 100 \
--effect preload_elastic --seed 3 --out prod.csv"
)]
pub struct SimulateArgs {
    /// Comma-separated campaigns, measured one after the other into one file (optional for
    /// a bag with --stream-hz).
    #[arg(
        long,
        value_delimiter = ',',
        required_unless_present_any = ["stream_hz", "production_seconds", "plan"]
    )]
    pub campaign: Vec<String>,
    /// A planned campaign (`rpkm plan --out PLAN.csv`) to measure instead: its setups and
    /// poses in its order, on the twin (CSV --out only).
    #[arg(long, conflicts_with_all = ["campaign", "production_seconds", "stream_hz"])]
    pub plan: Option<PathBuf>,
    /// Hidden effects, NAME or NAME=MAGNITUDE, comma-separated (default magnitude if none).
    #[arg(long, value_delimiter = ',')]
    pub effect: Vec<String>,
    /// Seed of the true machine, the noise and the validation poses.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output: a campaign CSV if it ends in .csv, else a new bag folder.
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
    #[arg(long, conflicts_with = "noise")]
    pub no_noise: bool,
    /// The twin's noise, NAME=VALUE comma-separated (mm, rad for psi; the rest at the spec's
    /// figures): `lt` (isotropic tracker), `lt_along`, `lt_across`, `lt_across_per_m`, `kgm`,
    /// `dbb`, `li`, `psi`, `encoder`, `force` (N), `tracker_x`, `tracker_y`. A machine noisier than what
    /// the calibration assumes: `--noise encoder=0.0005,lt=0.006`.
    #[arg(long)]
    pub noise: Option<String>,
    /// Bag only: also write an ActuatorState stream at this rate (Hz) on
    /// /rpkm/actuator_state, after the campaign (if any) on the twin's clock.
    #[arg(long)]
    pub stream_hz: Option<f64>,
    /// Length of the stream, s.
    #[arg(long, default_value_t = 1.0)]
    pub stream_seconds: f64,
    /// Commanded path during the stream.
    #[arg(long, value_enum, default_value_t = crate::stream::Motion::Circle)]
    pub stream_motion: crate::stream::Motion,
    /// A drive whose carrier drifts from its encoder during the stream, qN=MM, ramped from 0
    /// to MM (e.g. q3=0.8: with preload_elastic the drives then fight, the redundancy
    /// current grows; 0.4 mm on q3 is about 100 %).
    #[arg(long)]
    pub fault: Option<crate::stream::Fault>,
    /// A production stream instead of campaigns (issue 15): this many seconds of a
    /// machining-like path (random contour moves at 50 mm/s), all drives active (give
    /// --effect preload_elastic), force noise, a drifting temperature, sampled at --stream-hz
    /// (default 1000) and written every --production-decimate-th sample as a campaign CSV
    /// (instrument none, f1..f4, temp_machine), with the truth over time beside it in
    /// OUT.truth.csv (true TCP, noiseless forces and the 29 true parameters per row).
    #[arg(long)]
    pub production_seconds: Option<f64>,
    /// Temperature drift of the production stream, K/h.
    #[arg(long, default_value_t = 4.0)]
    pub production_drift: f64,
    /// A crash during the production stream: PARAM=CHANGE@SECONDS (mm or rad), e.g.
    /// l3=0.1@2400 bends rod 3 by 0.1 mm at 40 min.
    #[arg(long)]
    pub production_step: Option<String>,
    /// Write one production sample in this many.
    #[arg(long, default_value_t = 1)]
    pub production_decimate: usize,
    /// Bag only: compress chunks with zstd.
    #[arg(long)]
    pub zstd: bool,
}

/// Whether `--out` names a campaign CSV (else a bag folder).
pub fn is_csv(out: &Path) -> bool {
    out.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
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
        .map_err(|e: rpkm_core::effects::UnknownEffect| super::bad_input(e.to_string()))?;
    let m = match mag {
        Some(m) => m.trim().parse::<f64>().map_err(|_| {
            super::bad_input(format!("magnitude of effect {name}: {m:?} is not a number"))
        })?,
        None => kind.default_magnitude(),
    };
    Ok((kind, m))
}

/// The twin's noise from `--noise` / `--no-noise`.
fn twin_noise(args: &SimulateArgs) -> Result<Option<NoiseModel>> {
    if args.no_noise {
        return Ok(None);
    }
    let spec = args.noise.as_deref().unwrap_or("");
    NoiseModel::parse(spec)
        .map(Some)
        .map_err(|e| super::bad_input(format!("--noise: {e}")))
}

/// `dir/name.csv` → `dir/name.val.csv`.
fn validation_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or_else(|| "campaign".into(), |s| s.to_string_lossy().into_owned());
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
        noise: twin_noise(args)?,
        ..TwinConfig::default()
    })?;
    if let Some(seconds) = args.production_seconds {
        return run_production(args, &twin, seconds);
    }
    if let Some(plan) = &args.plan {
        return run_plan(args, &mut twin, plan);
    }
    let names: Vec<&str> = args.campaign.iter().map(|s| s.trim()).collect();
    if !is_csv(&args.out) {
        return super::simulate_bag::run(args, &mut twin, &names);
    }
    if args.stream_hz.is_some() || args.fault.is_some() {
        return Err(super::bad_input(format!(
            "--stream-hz and --fault need a bag: --out {} ends in .csv",
            args.out.display()
        )));
    }
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

/// `--plan`: a planned campaign measured on the twin.
fn run_plan(args: &SimulateArgs, twin: &mut Twin, plan: &Path) -> Result<()> {
    if !is_csv(&args.out) {
        return Err(super::bad_input(format!(
            "--plan needs a CSV --out, not {}",
            args.out.display()
        )));
    }
    let text = std::fs::read_to_string(plan)
        .map_err(|e| super::bad_input(format!("{}: cannot read the plan: {e}", plan.display())))?;
    let design = rpkm_core::plan::csv::parse(&text, &plan.display().to_string())?;
    let c = twin.run(&design, &args.out.display().to_string())?;
    std::fs::write(&args.out, c.to_csv())
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!(
        "{}: {} poses of {} measured",
        args.out.display(),
        c.poses.len(),
        plan.display()
    );
    if let Some(path) = &args.truth {
        super::write_json(path, &serde_json::to_value(twin.truth())?)?;
    }
    Ok(())
}

/// A production stream's crash `PARAM=CHANGE@SECONDS`.
fn parse_step(s: &str) -> Result<rpkm_core::twin::StepChange> {
    let bad = || {
        super::bad_input(format!(
            "--production-step {s}: expected PARAM=CHANGE@SECONDS, e.g. l3=0.1@2400"
        ))
    };
    let (name, rest) = s.split_once('=').ok_or_else(bad)?;
    let (change, at) = rest.split_once('@').ok_or_else(bad)?;
    let param = rpkm_core::params::index_of(name.trim()).ok_or_else(|| {
        super::bad_input(format!("--production-step: unknown parameter `{name}`"))
    })?;
    let change: f64 = change.trim().parse().map_err(|_| bad())?;
    let at_s: f64 = at.trim().parse().map_err(|_| bad())?;
    if !change.is_finite() || !at_s.is_finite() || at_s < 0.0 {
        return Err(bad());
    }
    Ok(rpkm_core::twin::StepChange {
        at_s,
        param,
        change,
    })
}

/// `--production-seconds`: the stream as a campaign CSV and its truth beside it.
fn run_production(args: &SimulateArgs, twin: &Twin, seconds: f64) -> Result<()> {
    use rpkm_core::campaign::{Campaign, Instrument, Pose};
    use rpkm_core::params::{NAMES, N_PARAMS};
    use rpkm_core::twin::{ProductionConfig, ProductionStream};
    use std::fmt::Write as _;
    if !(is_csv(&args.out) && seconds > 0.0 && seconds <= 86_400.0) {
        return Err(super::bad_input(format!(
            "--production-seconds {seconds}: a CSV --out and 0 < seconds <= 86400"
        )));
    }
    let cfg = ProductionConfig {
        rate_hz: args.stream_hz.unwrap_or(1000.0),
        seconds,
        drift_k_per_h: args.production_drift,
        step: args
            .production_step
            .as_deref()
            .map(parse_step)
            .transpose()?,
        seed: args.seed,
        ..Default::default()
    };
    let every = args.production_decimate.max(1);
    let mut poses = Vec::new();
    let mut truth = String::from("t,x,y,psi,f1,f2,f3,f4");
    for n in &NAMES {
        let _ = write!(truth, ",{n}");
    }
    truth.push('\n');
    for (k, s) in ProductionStream::new(twin, cfg).enumerate() {
        let s = s?;
        if k % every != 0 {
            continue;
        }
        poses.push(Pose {
            t: s.t,
            setup: "production".into(),
            instrument: Instrument::None,
            reset: false,
            q: s.q,
            f: s.f,
            follower: [false; 4],
            x: None,
            y: None,
            r: None,
            psi: None,
            covariates: vec![Some(s.temp_c)],
            line: poses.len() + 2,
        });
        let _ = write!(truth, "{},{},{},{}", s.t, s.tcp[0], s.tcp[1], s.tcp[2]);
        for f in s.f_true {
            let _ = write!(truth, ",{f}");
        }
        for i in 0..N_PARAMS {
            let _ = write!(truth, ",{}", s.truth[i]);
        }
        truth.push('\n');
    }
    let c = Campaign {
        source: args.out.display().to_string(),
        comments: vec![format!(
            "production stream, seed {}, {seconds} s",
            args.seed
        )],
        covariate_names: vec!["temp_machine".into()],
        poses,
    };
    std::fs::write(&args.out, c.to_csv())
        .with_context(|| format!("writing {}", args.out.display()))?;
    let truth_path = args.out.with_extension("truth.csv");
    std::fs::write(&truth_path, truth)
        .with_context(|| format!("writing {}", truth_path.display()))?;
    println!(
        "{}: {} production samples; truth over time: {}",
        args.out.display(),
        c.poses.len(),
        truth_path.display()
    );
    Ok(())
}
