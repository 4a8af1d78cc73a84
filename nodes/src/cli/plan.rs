//! `rpkm plan`: what to measure next (the planner is `rpkm_core::plan`).

use super::{bad_input, read_campaign, write_json};
use anyhow::Context;
use rpkm_core::calib::{self, Options, Prior, Selection};
use rpkm_core::campaign::Instrument;
use rpkm_core::params::{Model, Params};
use rpkm_core::plan::separate::{self, Hypothesis, Pair, SeparationPlan};
use rpkm_core::plan::{self, csv, DeterminationPlan, Start, Unknowns};
use rpkm_core::variance;
use serde_json::json;
use std::path::PathBuf;

/// Plan the next measurements: calibrate the campaign (tolerance prior, noise estimated from
/// it), then choose the poses, instruments and setups that determine most of what it left
/// undetermined (greedy D-optimal, a setup's reset pose paid when it is opened), or with
/// --separate the sequence of poses that tells two tied explanations apart (T-optimal).
/// Writes PLAN.csv (the campaign grammar without measured values: setup, instrument, reset,
/// follower, target x, y) that `rpkm simulate --plan` runs on the twin.
///
/// Examples:
///   rpkm plan self.csv --instruments lt --budget 20 --out plan.csv
///   rpkm plan self.csv --separate dir_q2,dir_q4 --budget 60 --out sep.csv --json sep.json
#[derive(clap::Args, Debug, Clone)]
pub struct PlanArgs {
    /// The campaign measured so far (CSV).
    pub campaign: PathBuf,
    /// Parameter model: 24 or 29.
    #[arg(long, default_value_t = 29)]
    pub model: u32,
    /// Instruments the plan may use, comma-separated: lt, kgm, dbb, psi (platform angle),
    /// self (q2, q3 followers). Default: lt, or self with --separate.
    #[arg(long, value_delimiter = ',')]
    pub instruments: Vec<String>,
    /// Poses to plan (a relative setup's reset pose counts as one).
    #[arg(long, default_value_t = 20)]
    pub budget: usize,
    /// Two explanations to separate, A,B: dir_q1..dir_q4 (lost motion of a carrier) or
    /// parameter names (l1, gamma2, ...).
    #[arg(long, value_delimiter = ',')]
    pub separate: Vec<String>,
    /// Size of a lost motion the separation is judged at, mm.
    #[arg(long, default_value_t = 0.01)]
    pub lost_motion_mm: f64,
    /// Stated noise (as `rpkm calibrate --noise`); the campaign re-estimates what it shows.
    #[arg(long)]
    pub noise: Option<String>,
    /// Where to write PLAN.csv.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where to write the plan as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
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

pub fn run(args: &PlanArgs) -> anyhow::Result<()> {
    let model = Model::from_number(args.model)
        .ok_or_else(|| bad_input(format!("--model {}: expected 24 or 29", args.model)))?;
    if args.budget == 0 || args.budget > 10_000 {
        return Err(bad_input(format!(
            "--budget {}: expected 1 to 10000",
            args.budget
        )));
    }
    let prior = Prior::default();
    // the arguments checked before the campaign is calibrated
    let instruments = instruments(args)?;
    let pair = (!args.separate.is_empty())
        .then(|| pair(args, &prior))
        .transpose()?;
    let campaign = read_campaign(&args.campaign)?;
    let opts = Options {
        model,
        selection: Selection::Prior(prior),
        noise: super::parse_noise(args.noise.as_deref())?,
        ..Default::default()
    };
    let (cal, noise) = calibrate(&campaign, &opts)
        .with_context(|| format!("calibrating {}", args.campaign.display()))?;
    let start = Start {
        campaign: &campaign,
        params: &cal.params,
        model,
        noise: &noise.model,
    };
    let unknowns = Unknowns::of_model(model, |i| prior.sigma(i));
    let Some(pair) = pair else {
        let p = plan::plan_determination(&start, &unknowns, &instruments, args.budget)?;
        print_determination(&p, cal.determined);
        return write_outputs(args, &p.design(), &determination_comments(&p), || {
            determination_json(&p)
        });
    };
    run_separation(args, &start, &unknowns, instruments[0], &pair)
}

/// `--separate`: how far the campaign tells the pair apart, and the sequence of poses of
/// the first instrument's setup that tells them apart most.
fn run_separation(
    args: &PlanArgs,
    start: &Start,
    unknowns: &Unknowns,
    instrument: Instrument,
    pair: &Pair,
) -> anyhow::Result<()> {
    let at = (start.model, start.noise);
    let before = separate::separation_of(start.campaign, start.params, at, unknowns, pair)?;
    let setup = plan::candidates(&[instrument])?.remove(0);
    let p = separate::separate(&setup, start.params, at, unknowns, pair, args.budget)?;
    print_separation(pair, before, &p);
    let comments = vec![format!(
        "rpkm plan: separates {} from {} (now {:.2} sigma, after the plan {:.2} sigma, at {} and {})",
        pair.a,
        pair.b,
        before.sigma(),
        p.after().map_or(0.0, |s| s.sigma()),
        size_words(pair.a, pair.size[0]),
        size_words(pair.b, pair.size[1]),
    )];
    write_outputs(args, &p.poses, &comments, || {
        separation_json(pair, before, &p)
    })
}

/// The one calibration of the plan: tolerance prior, the noise estimated from the campaign.
fn calibrate(
    campaign: &rpkm_core::campaign::Campaign,
    opts: &Options,
) -> Result<(calib::Calibration, variance::NoiseEstimate), calib::CalibrationError> {
    let start = Params::nominal();
    calib::calibrate(&calib::Request {
        noise: calib::Noise::ESTIMATE,
        ..calib::Request::new(campaign, &start, opts)
    })
}

fn pair(args: &PlanArgs, prior: &Prior) -> anyhow::Result<Pair> {
    let [a, b] = args.separate.as_slice() else {
        return Err(bad_input(format!(
            "--separate {}: expected two hypotheses A,B",
            args.separate.join(",")
        )));
    };
    if !(args.lost_motion_mm.is_finite() && args.lost_motion_mm > 0.0) {
        return Err(bad_input(format!(
            "--lost-motion-mm {}: expected a positive number",
            args.lost_motion_mm
        )));
    }
    let parse = |s: &str| {
        s.parse::<Hypothesis>()
            .map_err(|e| bad_input(format!("--separate: {e}")))
    };
    Pair::new(parse(a)?, parse(b)?, args.lost_motion_mm, &|i| {
        prior.sigma(i)
    })
    .map_err(|e| bad_input(format!("--separate: {e}")))
}

fn size_words(h: Hypothesis, size: f64) -> String {
    match h {
        Hypothesis::LostMotion(_) => format!("{h} = {:.1} um", size * 1e3),
        Hypothesis::Parameter(_) => format!("{h} at its tolerance {size}"),
    }
}

/// PLAN.csv and the JSON, where asked for.
fn write_outputs(
    args: &PlanArgs,
    poses: &[rpkm_core::design::PlannedPose],
    comments: &[String],
    json: impl Fn() -> serde_json::Value,
) -> anyhow::Result<()> {
    if let Some(path) = &args.out {
        std::fs::write(path, csv::to_csv(poses, comments))
            .with_context(|| format!("writing {}", path.display()))?;
        println!("\nwrote {} ({} poses)", path.display(), poses.len());
    }
    if let Some(path) = &args.json {
        write_json(path, &json())?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

fn print_determination(p: &DeterminationPlan, calibrated: Option<(usize, usize)>) {
    let b = p.before;
    println!(
        "now: {} of {} parameter combinations determined better than their tolerance (effective {:.1})",
        b.determined, b.of, b.effective
    );
    if let Some((d, n)) = calibrated {
        println!("     (the calibration's own count: {d} of {n})");
    }
    println!("\nplan:");
    for s in &p.setups {
        let reset = s.setup.reset.map_or(String::from("no reset"), |(x, y)| {
            format!("reset at ({x:.0}, {y:.0})")
        });
        println!(
            "  {:<14} {:<6} {:>3} poses, {reset}: then {} of {} determined (effective {:.1})",
            s.setup.id,
            s.setup.instrument.as_str(),
            s.poses,
            s.after.determined,
            s.after.of,
            s.after.effective
        );
    }
    let a = p.after();
    println!(
        "\nafter the plan: {} of {} determined (+{})",
        a.determined,
        a.of,
        a.determined.saturating_sub(b.determined)
    );
}

fn determination_comments(p: &DeterminationPlan) -> Vec<String> {
    let mut out = vec![format!(
        "rpkm plan: now {} of {} parameter combinations determined; x, y are target TCP positions (mm), nothing measured yet",
        p.before.determined, p.before.of
    )];
    for s in &p.setups {
        out.push(format!(
            "setup {} ({}, {} poses): then {} of {} determined",
            s.setup.id,
            s.setup.instrument.as_str(),
            s.poses,
            s.after.determined,
            s.after.of
        ));
    }
    out
}

fn determination_json(p: &DeterminationPlan) -> serde_json::Value {
    json!({
        "kind": "determine",
        "before": p.before,
        "after": p.after(),
        "setups": p.setups.iter().map(|s| json!({
            "setup": s.setup.id,
            "instrument": s.setup.instrument.as_str(),
            "reset": s.setup.reset.map(|(x, y)| [x, y]),
            "poses": s.poses,
            "points": s.points.iter().map(|&k| s.setup.points[k]).map(|(x, y)| [x, y]).collect::<Vec<_>>(),
            "after": s.after,
        })).collect::<Vec<_>>(),
    })
}

fn print_separation(pair: &Pair, before: separate::Separation, p: &SeparationPlan) {
    println!(
        "{} against {}: the campaign tells them apart by {:.2} sigma ({} true: {:.2}, {} true: {:.2})",
        pair.a, pair.b, before.sigma(), pair.a, before.a_from_b, pair.b, before.b_from_a
    );
    println!(
        "judged at {} and {}",
        size_words(pair.a, pair.size[0]),
        size_words(pair.b, pair.size[1])
    );
    if let Some(after) = p.after() {
        println!(
            "\nplan: {} poses; measured alone they tell them apart by {:.2} sigma ({:.2}, {:.2})",
            p.poses.len(),
            after.sigma(),
            after.a_from_b,
            after.b_from_a
        );
        for k in [4, 9, 19, 39]
            .into_iter()
            .filter(|&k| k < p.after_each.len())
        {
            println!(
                "  after {:>3} poses: {:.2} sigma",
                k + 1,
                p.after_each[k].sigma()
            );
        }
    }
}

fn separation_json(
    pair: &Pair,
    before: separate::Separation,
    p: &SeparationPlan,
) -> serde_json::Value {
    json!({
        "kind": "separate",
        "a": pair.a.to_string(),
        "b": pair.b.to_string(),
        "size": pair.size,
        "before": before,
        "before_sigma": before.sigma(),
        "after": p.after(),
        "after_sigma": p.after().map(|s| s.sigma()),
        "after_each_sigma": p.after_each.iter().map(separate::Separation::sigma).collect::<Vec<_>>(),
        "poses": p.poses.iter().map(|q| json!({"setup": q.setup, "x": q.x, "y": q.y})).collect::<Vec<_>>(),
    })
}
