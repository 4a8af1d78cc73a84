//! `rpkm simulate`: measurement campaigns from the digital twin.

use anyhow::{bail, Context, Result};
use rpkm_core::campaign::Instrument;
use rpkm_core::noise::{NoiseModel, XyInstrument};
use rpkm_twin::{EffectKind, Twin, TwinConfig, ZeroDrift};
use std::path::{Path, PathBuf};

mod args;
mod bag;

pub use args::SimulateArgs;

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

/// `--drift INSTRUMENT=VX,VY` (µm/min, µrad/min for li_psi; one value for a
/// single-coordinate instrument) as the twin's drift per second in mm (rad).
pub fn parse_drift(s: &str) -> Result<ZeroDrift> {
    let bad = |why: &str| super::bad_input(format!("--drift {s}: {why}"));
    let (name, rates) = s
        .split_once('=')
        .ok_or_else(|| bad("expected INSTRUMENT=VX,VY (µm/min), e.g. lt=0,1"))?;
    let instrument: Instrument = name
        .trim()
        .parse()
        .ok()
        .filter(|i: &Instrument| i.is_relative())
        .ok_or_else(|| bad("expected a relative instrument: lt, kgm, dbb, li_x, li_y or li_psi"))?;
    let values = rates
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| bad("a rate is not a finite number"))?;
    let two = XyInstrument::of(instrument).is_some();
    let rate = match (two, values.as_slice()) {
        (true, [vx, vy]) => [*vx, *vy],
        (false, [v]) => [*v, 0.0],
        (true, _) => return Err(bad("expected two rates VX,VY for a 2-D instrument")),
        (false, _) => return Err(bad("expected one rate for a single-coordinate instrument")),
    };
    // µm/min (µrad/min) → mm/s (rad/s)
    let per_s = if instrument == Instrument::LiPsi {
        1e-6 / 60.0
    } else {
        1e-3 / 60.0
    };
    Ok(ZeroDrift {
        instrument,
        rate_per_s: rate.map(|v| v * per_s),
    })
}

/// The twin's stiffness from `--rod-stiffness ROD=FACTOR,...`.
pub fn parse_rod_stiffness(items: &[String]) -> Result<rpkm_core::elastic::Stiffness> {
    let mut stiffness = rpkm_core::elastic::Stiffness::default();
    for item in items.iter().filter(|s| !s.trim().is_empty()) {
        let bad = |why: &str| super::bad_input(format!("--rod-stiffness {item}: {why}"));
        let (rod, factor) = item
            .split_once('=')
            .ok_or_else(|| bad("expected ROD=FACTOR, e.g. 3=1.3"))?;
        let rod: usize = rod
            .trim()
            .parse()
            .ok()
            .filter(|r| (1..=5).contains(r))
            .ok_or_else(|| bad("the rod is a number 1..5"))?;
        let factor: f64 = factor
            .trim()
            .parse()
            .ok()
            .filter(|f: &f64| f.is_finite() && *f > 0.0)
            .ok_or_else(|| bad("the factor is a positive number"))?;
        stiffness.rod[rod - 1] *= factor;
    }
    Ok(stiffness)
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
        drift: args.drift.as_deref().map(parse_drift).transpose()?,
        stiffness: parse_rod_stiffness(&args.rod_stiffness)?,
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
        return bag::run(args, &mut twin, &names);
    }
    if args.stream_hz.is_some() || args.fault.is_some() || args.record_parameters {
        return Err(super::bad_input(format!(
            "--stream-hz, --fault and --record-parameters need a bag: --out {} ends in .csv",
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
fn parse_step(s: &str) -> Result<rpkm_twin::StepChange> {
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
    Ok(rpkm_twin::StepChange {
        at_s,
        param,
        change,
    })
}

/// A commanded motion `X,Y;X,Y;...@SECONDS` (mm) with `dwell_s` at each pose.
fn parse_visit(s: &str, dwell_s: f64) -> Result<rpkm_twin::Visit> {
    use rpkm_core::design::{X_RANGE, Y_RANGE};
    let bad = |why: &str| {
        super::bad_input(format!(
            "--production-visit {s}: {why}; expected X,Y;X,Y;...@SECONDS in mm, e.g. \
             -150,2000;150,1600@36.9"
        ))
    };
    let (poses, at) = s.split_once('@').ok_or_else(|| bad("no @SECONDS"))?;
    let at_s: f64 = at
        .trim()
        .parse()
        .map_err(|_| bad("SECONDS is not a number"))?;
    if !at_s.is_finite() || at_s < 0.0 {
        return Err(bad("SECONDS must be 0 or more"));
    }
    if !dwell_s.is_finite() || dwell_s < 0.0 {
        return Err(super::bad_input(format!(
            "--production-dwell {dwell_s}: seconds, 0 or more"
        )));
    }
    let poses = poses
        .split(';')
        .enumerate()
        .map(|(i, pose)| {
            let (x, y) = pose
                .split_once(',')
                .ok_or_else(|| bad(&format!("pose {} `{pose}` is not X,Y", i + 1)))?;
            let (x, y): (f64, f64) = match (x.trim().parse(), y.trim().parse()) {
                (Ok(x), Ok(y)) => (x, y),
                _ => return Err(bad(&format!("pose {} `{pose}` is not two numbers", i + 1))),
            };
            let inside =
                (X_RANGE.0..=X_RANGE.1).contains(&x) && (Y_RANGE.0..=Y_RANGE.1).contains(&y);
            if !inside {
                return Err(bad(&format!(
                    "pose {} ({x}, {y}) is outside the workspace x {:?}, y {:?} mm",
                    i + 1,
                    X_RANGE,
                    Y_RANGE
                )));
            }
            Ok((x, y))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(rpkm_twin::Visit {
        at_s,
        poses,
        dwell_s,
    })
}

/// The production stream the arguments describe.
fn production_config(args: &SimulateArgs, seconds: f64) -> Result<rpkm_twin::ProductionConfig> {
    Ok(rpkm_twin::ProductionConfig {
        rate_hz: args.stream_hz.unwrap_or(1000.0),
        seconds,
        drift_k_per_h: args.production_drift,
        step: args
            .production_step
            .as_deref()
            .map(parse_step)
            .transpose()?,
        visit: args
            .production_visit
            .as_deref()
            .map(|v| parse_visit(v, args.production_dwell))
            .transpose()?,
        seed: args.seed,
        ..Default::default()
    })
}

/// `--production-seconds`: the stream as a campaign CSV and its truth beside it.
fn run_production(args: &SimulateArgs, twin: &Twin, seconds: f64) -> Result<()> {
    use rpkm_core::campaign::{Campaign, Instrument, MeasuredPose};
    use rpkm_core::params::{NAMES, N_PARAMS};
    use rpkm_twin::ProductionStream;
    use std::fmt::Write as _;
    if !(is_csv(&args.out) && seconds > 0.0 && seconds <= 86_400.0) {
        return Err(super::bad_input(format!(
            "--production-seconds {seconds}: a CSV --out and 0 < seconds <= 86400"
        )));
    }
    let cfg = production_config(args, seconds)?;
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
        poses.push(MeasuredPose {
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
