//! `rpkm plan`: what to measure next (the planner is `rpkm_core::plan`).

mod accuracy;
mod args;
mod determine;
mod output;

pub use args::PlanArgs;

use super::effect_stages::{parse_effects, read_effects_file};
use super::{bad_input, read_campaign};
use anyhow::Context;
use output::Drives;
use rpkm_core::calib::{self, CommandError, CommandRequest, Options, Prior, Selection};
use rpkm_core::campaign::{parse_follower, Campaign, Instrument};
use rpkm_core::effects::Effect;
use rpkm_core::params::{Model, Params};
use rpkm_core::plan::forecast::targets_of;
use rpkm_core::plan::separate::{Hypothesis, Pair};
use rpkm_core::plan::{self, csv, Preload, Start, TargetForecast, Unknowns};
use rpkm_core::variance;

/// What a plan is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Criterion {
    Tcp,
    Determinant,
}

/// `--instruments`: the spec's names, `psi` for the angle optics.
fn instruments(args: &PlanArgs) -> anyhow::Result<Vec<Instrument>> {
    let default = if args.separate.is_empty() {
        "lt"
    } else {
        "self"
    };
    let names: Vec<&str> = if args.instruments.is_empty() {
        vec![default]
    } else {
        args.instruments.iter().map(|s| s.trim()).collect()
    };
    names
        .into_iter()
        .map(|n| match n {
            "psi" => Ok(Instrument::LiPsi),
            "lt" | "kgm" | "dbb" | "self" => n
                .parse()
                .map_err(|e: rpkm_core::campaign::ParseInstrumentError| bad_input(e.0)),
            other => Err(bad_input(format!(
                "--instruments {other}: expected lt, kgm, dbb, psi or self"
            ))),
        })
        .collect()
}

/// The arguments checked before the campaign is calibrated.
struct Checked {
    model: Model,
    criterion: Criterion,
    instruments: Vec<Instrument>,
    pair: Option<Pair>,
    follower: Option<[bool; 4]>,
}

fn check(args: &PlanArgs, prior: &Prior) -> anyhow::Result<Checked> {
    let model = Model::from_number(args.model)
        .ok_or_else(|| bad_input(format!("--model {}: expected 24 or 29", args.model)))?;
    if let Some(&b) = args.budget.iter().find(|&&b| b == 0 || b > 10_000) {
        return Err(bad_input(format!("--budget {b}: expected 1 to 10000")));
    }
    let criterion = match args.criterion.as_str() {
        "tcp" => Criterion::Tcp,
        "determinant" => Criterion::Determinant,
        other => {
            return Err(bad_input(format!(
                "--criterion {other}: expected tcp or determinant"
            )))
        }
    };
    let follower = args
        .follower
        .as_deref()
        .map(|f| {
            parse_follower(f).ok_or_else(|| {
                bad_input(format!(
                    "--follower {f}: expected drive digits such as 23, or none (all four active)"
                ))
            })
        })
        .transpose()?;
    Ok(Checked {
        model,
        criterion,
        instruments: instruments(args)?,
        pair: (!args.separate.is_empty())
            .then(|| pair(args, prior))
            .transpose()?,
        follower,
    })
}

pub fn run(args: &PlanArgs) -> anyhow::Result<()> {
    let prior = args.tolerance.prior()?;
    let checked = check(args, &prior)?;
    let model = checked.model;
    let campaign = read_campaign(&args.campaign)?;
    let file = read_effects_file(args.effects_file.as_deref(), &[Some(&campaign)])?;
    let effects = parse_effects(&args.effects, file.as_ref())?;
    let refs: Vec<&dyn Effect> = effects.iter().map(AsRef::as_ref).collect();
    let opts = Options {
        model,
        selection: Selection::Prior(prior),
        noise: super::parse_noise(args.noise.as_deref())?,
        ..Default::default()
    };
    let (cal, noise) = calibrate(&campaign, &opts, &refs)
        .with_context(|| format!("calibrating {}", args.campaign.display()))?;
    let preload = Preload::of(&refs);
    let mode = plan::drive_mode(&campaign, preload, checked.follower);
    let drives = Drives {
        words: output::mode_words(&mode, preload),
        mode,
    };
    println!("{}\n", drives.words);
    let start = Start {
        campaign: &campaign,
        params: &cal.params,
        model,
        noise: &noise.model,
    };
    let unknowns = Unknowns::of_model(model, |i| prior.sigma(i));
    let last = args.budget.last().copied().unwrap_or(20);
    let both = (&start, &unknowns);
    if let Some(pair) = checked.pair {
        let instrument = checked.instruments[0];
        return determine::run_separation(args, both, (instrument, &drives), &pair, last);
    }
    let instruments = checked.instruments.as_slice();
    if checked.criterion == Criterion::Determinant {
        return determine::run_determination(
            args,
            both,
            (instruments, &drives),
            cal.determined,
            last,
        );
    }
    let (evaluation, words) = evaluation(args, &start, &unknowns)?;
    accuracy::run(args, both, (instruments, &drives), (&evaluation, &words))
}

/// Where the TCP is judged: the grid, or the poses of `--where`; and its words.
fn evaluation(
    args: &PlanArgs,
    start: &Start,
    unknowns: &Unknowns,
) -> anyhow::Result<(TargetForecast, String)> {
    let at = (start.model, start.noise);
    let Some(path) = &args.where_ else {
        let e = TargetForecast::grid(start.params, at, unknowns)?;
        return Ok((
            e,
            "a tracker setup at the workspace's 231 grid poses".to_owned(),
        ));
    };
    let text = std::fs::read_to_string(path)
        .map_err(|e| bad_input(format!("{}: cannot read --where: {e}", path.display())))?;
    let source = path.display().to_string();
    let first = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .unwrap_or("");
    let targets = if first.replace(' ', "") == csv::TARGETS_HEADER {
        csv::parse_targets(&text, &source).map_err(|e| bad_input(e.to_string()))?
    } else {
        let c = Campaign::parse(&text, &source).map_err(anyhow::Error::new)?;
        targets_of(&c, start.params, start.model).map_err(|e| bad_input(e.to_string()))?
    };
    let n = targets.len();
    let e = TargetForecast::new(targets, start.params, at, unknowns)
        .map_err(|e| bad_input(format!("{source}: {e}")))?;
    Ok((e, format!("a tracker setup at the {n} poses of {source}")))
}

/// The one calibration of the plan: tolerance prior, the noise estimated from the campaign,
/// the effects in the model.
fn calibrate(
    campaign: &Campaign,
    opts: &Options,
    effects: &[&dyn Effect],
) -> anyhow::Result<(calib::Calibration, variance::NoiseEstimate)> {
    let start = Params::nominal();
    let done = calib::calibrate_command(&CommandRequest::new(campaign, &start, opts, effects))
        .map_err(|e| match e {
            CommandError::Effects(e) => bad_input(format!("--effects: {e}")),
            CommandError::Calibration(e) => anyhow::Error::new(e),
        })?;
    Ok((done.calibration, done.noise))
}

fn pair(args: &PlanArgs, prior: &Prior) -> anyhow::Result<Pair> {
    let [a, b] = args.separate.as_slice() else {
        return Err(bad_input(format!(
            "--separate {}: expected two hypotheses A,B",
            args.separate.join(",")
        )));
    };
    super::prior_args::positive("--lost-motion-mm", args.lost_motion_mm)?;
    let parse = |s: &str| {
        s.parse::<Hypothesis>()
            .map_err(|e| bad_input(format!("--separate: {e}")))
    };
    Pair::new(parse(a)?, parse(b)?, args.lost_motion_mm, &|i| {
        prior.sigma(i)
    })
    .map_err(|e| bad_input(format!("--separate: {e}")))
}
