//! `rpkm bench plan`: does a plan pay? On twin machines from a self-calibration base, the
//! tracker poses `rpkm plan` chooses for the TCP against as many random ones, each measured
//! with several noise seeds on the same machine, every calibration judged on one held-out
//! tracker setup by its RMS with the setup's zero removed (the diagnosis's
//! `val_rms_relative_um`), beside the expected held-out RMS the plan printed.

use anyhow::Result;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rpkm_core::calib::{self, CommandError, CommandRequest, Options, Prior, Selection};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::design::{self, PlannedPose, CENTRE, X_RANGE, Y_RANGE};
use rpkm_core::diagnose::HeldOutErrors;
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{Model, Params};
use rpkm_core::plan::{self, AccuracyPlanner, Start, TargetForecast, Unknowns};
use rpkm_core::units::{rad_from_mrad, um_from_mm};
use rpkm_twin::{Twin, TwinConfig};

/// Measure the plan's tracker poses against random ones on twin machines.
///
/// Each machine (its parameter errors drawn from its seed) is measured by self-calibration,
/// calibrated (tolerance prior, noise estimated, the tracker's noise stated as --noise
/// states it), planned for (`rpkm plan`'s TCP criterion, each budget), and then, for every
/// noise seed, the plan's poses and as many random poses (a reset at the workspace centre,
/// the others uniform over the workspace, one tracker setup) are measured on the same
/// machine with that seed's noise, each calibrated with the self rows and judged on the same
/// held-out tracker setup. Prints per machine and budget the median held-out RMS of each
/// (each setup's zero removed) and the plan's expected one.
///
/// Example: rpkm bench plan --machines 6 --seeds 6 --budgets 5,10 --noise lt=0.005
#[derive(clap::Args, Debug)]
pub struct PlanStudyArgs {
    #[arg(long, default_value_t = 6)]
    pub machines: u64,
    /// Noise seeds per machine and budget.
    #[arg(long, default_value_t = 6)]
    pub seeds: u64,
    #[arg(long, value_delimiter = ',', default_value = "5,10")]
    pub budgets: Vec<usize>,
    /// The twin's noise, and what the calibration and the plan are told of it (NAME=VALUE,
    /// as `rpkm simulate --noise`; default: an isotropic 5 µm tracker).
    #[arg(long, default_value = "lt=0.005")]
    pub noise: String,
    /// The tolerance prior's angles, mrad (the calibrations' and the plan's; the twin draws
    /// its angle errors with σ 0.2 mrad, the calibration's default tolerance is 1 mrad).
    #[arg(long, default_value_t = 1.0)]
    pub tolerance_mrad: f64,
    /// Poses of the held-out tracker setup.
    #[arg(long, default_value_t = 100)]
    pub held_out: usize,
    /// Seed of the first machine.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write every run's figures as JSON.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

const MODEL: Model = Model::M29;

/// One budget's run on one machine with one noise seed, µm.
#[derive(Clone, Copy, Debug, serde::Serialize)]
struct Run {
    machine: u64,
    seed: u64,
    budget: usize,
    now_expected_um: f64,
    now_measured_um: f64,
    expected_um: f64,
    plan_um: f64,
    random_um: f64,
    /// The same without the held-out readings' noise: the TCP's own error (the noiseless
    /// held-out setup, zero removed), and its expected part (the forecast less the floor).
    expected_true_um: f64,
    plan_true_um: f64,
    random_true_um: f64,
}

pub fn run(a: &PlanStudyArgs) -> Result<()> {
    if a.machines == 0 || a.seeds == 0 || a.budgets.iter().any(|&b| b < 2) {
        return Err(crate::cli::bad_input(
            "--machines and --seeds at least 1, every budget at least 2".into(),
        ));
    }
    let noise =
        NoiseModel::parse(&a.noise).map_err(|e| crate::cli::bad_input(format!("--noise: {e}")))?;
    let mut runs = Vec::new();
    for m in 0..a.machines {
        for s in 0..a.seeds {
            runs.extend(machine_runs(a, &noise, a.seed + m, s)?);
            eprint!(".");
        }
    }
    eprintln!();
    print_table(&runs, a);
    if let Some(path) = &a.json {
        crate::cli::write_json(path, &serde_json::to_value(&runs)?)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The calibration's options: tolerance prior, the noise stated as the twin's.
fn options(noise: &NoiseModel, prior: Prior) -> Options {
    Options {
        model: MODEL,
        selection: Selection::Prior(prior),
        noise: noise.clone(),
        ..Default::default()
    }
}

fn calibrate(
    c: &Campaign,
    noise: &NoiseModel,
    prior: Prior,
) -> Result<(calib::Calibration, NoiseModel)> {
    let start = Params::nominal();
    let opts = options(noise, prior);
    let done = calib::calibrate_command(&CommandRequest::new(c, &start, &opts, &[])).map_err(
        |e| match e {
            CommandError::Effects(e) => crate::cli::bad_input(e.to_string()),
            CommandError::Calibration(e) => anyhow::Error::new(e),
        },
    )?;
    Ok((done.calibration, done.noise.model))
}

/// The held-out RMS (µm) of parameters `p` with each setup's zero removed: the TCP errors
/// less their mean per setup and coordinate, as the diagnosis's `val_rms_relative_um`.
fn held_out_um(val: &Campaign, p: &Params) -> Result<f64> {
    Ok(um_from_mm(
        HeldOutErrors::of_geometry(val, p, MODEL)?.rms_relative,
    ))
}

/// `base` with `extra` measured after it, one campaign.
fn joined(base: &Campaign, extra: &Campaign) -> Campaign {
    let mut c = base.clone();
    let offset = c.poses.len();
    c.poses.extend(extra.poses.iter().cloned().map(|mut p| {
        p.line += offset;
        p
    }));
    c
}

/// A reset at the workspace centre and `n - 1` poses uniform over the workspace, one
/// tracker setup.
fn random_design(n: usize, seed: u64) -> Vec<PlannedPose> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut d = vec![PlannedPose::new("random_lt", Instrument::Lt, true, CENTRE)];
    for _ in 1..n {
        let at = (
            rng.gen_range(X_RANGE.0..=X_RANGE.1),
            rng.gen_range(Y_RANGE.0..=Y_RANGE.1),
        );
        d.push(PlannedPose::new("random_lt", Instrument::Lt, false, at));
    }
    d
}

/// Every budget on machine `machine` with noise seed `s`.
fn machine_runs(a: &PlanStudyArgs, noise: &NoiseModel, machine: u64, s: u64) -> Result<Vec<Run>> {
    let mut twin = Twin::new(TwinConfig {
        seed: machine,
        noise_seed: Some(machine.wrapping_mul(7919).wrapping_add(1000 + s)),
        noise: Some(noise.clone()),
        ..TwinConfig::default()
    })?;
    let base = twin.run(&design::self_cal(), "self")?;
    let val_design = design::validation(a.held_out, 0x7a1d + machine);
    let val = twin.clone().run(&val_design, "validation")?;
    // the same machine's held-out poses read without noise: the TCP's own error
    let clean = Twin::new(TwinConfig {
        seed: machine,
        noise: None,
        ..TwinConfig::default()
    })?
    .run(&val_design, "validation")?;
    let prior = Prior {
        angle_rad: rad_from_mrad(a.tolerance_mrad),
        ..Prior::default()
    };
    let (cal, estimated) = calibrate(&base, noise, prior)?;
    let start = Start {
        campaign: &base,
        params: &cal.params,
        model: MODEL,
        noise: &estimated,
    };
    let unknowns = Unknowns::of_model(MODEL, |i| prior.sigma(i));
    let evaluation = TargetForecast::grid(&cal.params, (MODEL, &estimated), &unknowns)?;
    let setups = plan::candidates(&[Instrument::Lt])?;
    let planner = AccuracyPlanner::new(&start, &unknowns, &setups, &evaluation)?;
    let mode = plan::drive_mode(&base, plan::Preload::NotModelled, None);
    let now_measured_um = held_out_um(&val, &cal.params)?;
    let mut out = Vec::new();
    for &budget in &a.budgets {
        let (p, forecast) = planner.plan(budget)?;
        let planned = plan::measured_in(p.design(), &mode);
        let random = random_design(budget, 31 * machine + 977 * s + budget as u64);
        let mut judged = [[0.0; 2]; 2];
        for (k, d) in [planned, random].iter().enumerate() {
            let measured = twin.clone().run(d, "added")?;
            let (cal, _) = calibrate(&joined(&base, &measured), noise, prior)?;
            judged[k] = [
                held_out_um(&val, &cal.params)?,
                held_out_um(&clean, &cal.params)?,
            ];
        }
        out.push(Run {
            machine,
            seed: s,
            budget,
            now_expected_um: um_from_mm(forecast.now_mm),
            now_measured_um,
            expected_um: um_from_mm(forecast.after_mm),
            plan_um: judged[0][0],
            random_um: judged[1][0],
            expected_true_um: um_from_mm(plan::own_error(forecast.after_mm, forecast.floor_mm)),
            plan_true_um: judged[0][1],
            random_true_um: judged[1][1],
        });
    }
    Ok(out)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn print_table(runs: &[Run], a: &PlanStudyArgs) {
    println!(
        "held-out RMS, each setup's zero removed (µm; median of {} noise seeds; twin noise \
         `{}`); `true`: the same poses read without noise (the TCP's own error):",
        a.seeds, a.noise
    );
    println!(
        "  {:>7} {:>5} {:>8} {:>8} | {:>8} {:>8} {:>8} {:>8} | {:>8} {:>8} {:>8}",
        "machine",
        "poses",
        "now exp",
        "now",
        "plan exp",
        "plan",
        "random",
        "exp/plan",
        "true exp",
        "plan",
        "random"
    );
    let (mut wins, mut true_wins, mut within, mut cells) = (0, 0, 0, 0);
    for m in 0..a.machines {
        for &b in &a.budgets {
            let mine: Vec<&Run> = runs
                .iter()
                .filter(|r| r.machine == a.seed + m && r.budget == b)
                .collect();
            let med = |f: &dyn Fn(&Run) -> f64| median(mine.iter().map(|r| f(r)).collect());
            let (plan_um, random_um, expected) = (
                med(&|r| r.plan_um),
                med(&|r| r.random_um),
                med(&|r| r.expected_um),
            );
            let (plan_true, random_true) = (med(&|r| r.plan_true_um), med(&|r| r.random_true_um));
            let ratio = expected / plan_um;
            cells += 1;
            wins += usize::from(plan_um <= random_um);
            true_wins += usize::from(plan_true <= random_true);
            within += usize::from((ratio - 1.0).abs() <= 0.25);
            println!(
                "  {:>7} {:>5} {:>8.2} {:>8.2} | {:>8.2} {:>8.2} {:>8.2} {:>8.2} | {:>8.2} {:>8.2} {:>8.2}",
                a.seed + m,
                b,
                med(&|r| r.now_expected_um),
                med(&|r| r.now_measured_um),
                expected,
                plan_um,
                random_um,
                ratio,
                med(&|r| r.expected_true_um),
                plan_true,
                random_true
            );
        }
    }
    println!(
        "plan at or below random: {wins} of {cells} (without the held-out noise: {true_wins} of \
         {cells}); expected within 25 % of measured: {within} of {cells}"
    );
    for &b in &a.budgets {
        let all: Vec<&Run> = runs.iter().filter(|r| r.budget == b).collect();
        let med = |f: &dyn Fn(&Run) -> f64| median(all.iter().map(|r| f(r)).collect());
        println!(
            "all machines, {b} poses: median plan {:.2} µm, random {:.2} µm, expected {:.2} µm; \
             without the held-out noise plan {:.2} µm, random {:.2} µm; the plan at or below \
             random in {} of {} runs",
            med(&|r| r.plan_um),
            med(&|r| r.random_um),
            med(&|r| r.expected_um),
            med(&|r| r.plan_true_um),
            med(&|r| r.random_true_um),
            all.iter().filter(|r| r.plan_um <= r.random_um).count(),
            all.len()
        );
    }
}
