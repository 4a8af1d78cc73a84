//! `rpkm bench discovery`: the discovery loop on random machines whose conventions are drawn
//! at random, so that a model that only fits our own choices shows it.

mod calibration;
mod plan;
mod soak;

use super::bad_input;
use anyhow::Result;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rpkm_core::calib;
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::diagnose::{self, Options, Prediction, VerdictKind};
use rpkm_core::effects::{self, Effect};
use rpkm_core::noise::{NoiseModel, N_GROUPS};
use rpkm_twin::{EffectKind, ThermalPhysics, Twin, TwinConfig};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Benchmarks of the product as a user meets it.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub which: Bench,
}

#[derive(clap::Subcommand, Debug)]
pub enum Bench {
    /// The discovery loop (diagnose, add the named effect, again) on N random machines from
    /// the twin, with conventions drawn at random per machine: every noise group 0.5x-3x the
    /// spec's figures (the diagnosis starts from the spec's), relative instruments zeroed on
    /// a noisy reading, which thermal parts expand and by how much, effect magnitudes from
    /// 0.3x to 3x their defaults, parameter errors. Classes: no hidden effect, one or two of
    /// the library, lost motion, a periodic scale error (1-5 µm, pitch 10-200 mm, any
    /// carrier), a rod softer or stiffer than the others with all drives active, an
    /// instrument alignment down to where it hardly matters. Prints the confusion matrix
    /// (hidden vs named), each class's share right, the machines where a named effect raised
    /// the held-out error, the false-alarm rate on machines with nothing hidden, and the
    /// held-out RMS after the loop divided by the true floor.
    ///
    /// Example: rpkm bench discovery --machines 200 --seed 1 --threads 2 --json bench.json
    Discovery(DiscoveryArgs),
    /// The launched node set (launch_scripts/rpkm.launch.yaml, source:=stdin) under an
    /// actuator stream written into ingest's stdin at the stream rate for SECONDS: counts the
    /// estimates lost and their gaps (at the observer, and in the estimator's and the
    /// monitor's input) and prints the resident memory of every process at the start, each
    /// quarter and the end. Exit 1 when an estimate was lost.
    ///
    /// Example: rpkm bench soak --seconds 180 --rate-hz 8000
    Soak(soak::SoakArgs),
    /// Calibration time, LM iterations and peak memory of `rpkm calibrate` on twin
    /// self-calibration campaigns of about 10³, 10⁴ and 10⁵ poses (child processes, on every
    /// core and on one), the same 10⁵ random-target poses in 10, 100 and 1,000 setups and a
    /// campaign of the foreign simulator's class of design (each against the best), the diagnosis of a 1,000-pose campaign with every library effect, and,
    /// when Python with scipy is there, a plain scipy least_squares script's fit against
    /// rpkm's fit of the same problem alone and against whole `rpkm calibrate` processes.
    ///
    /// Example: rpkm bench calibration --repeats 7,67,672
    Calibration(calibration::CalibrationArgs),
    /// Planned tracker poses against random ones on twin machines (`rpkm bench plan --help`).
    Plan(plan::PlanStudyArgs),
}

#[derive(clap::Args, Debug)]
pub struct DiscoveryArgs {
    #[arg(long, default_value_t = 50)]
    pub machines: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads (one machine each at a time).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Write every machine's outcome as JSON.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
    /// Run only machine I of the series and print every verdict of its loop (to look at
    /// one the table counts wrong).
    #[arg(long)]
    pub only: Option<usize>,
}

/// What one machine was and what the loop said.
#[derive(Clone, Debug, serde::Serialize)]
struct Outcome {
    machine: usize,
    class: Class,
    hidden: Vec<String>,
    named: Vec<String>,
    final_verdict: String,
    correct: bool,
    /// The largest relative rise of the held-out RMS from one model of the loop to the next
    /// (0: a named effect never raised it).
    largest_rise: f64,
    /// The same rise in standard errors of the fall (paired errors, as a diagnosis judges a
    /// candidate): above 2, the step predicts worse.
    largest_rise_se: f64,
    /// The held-out RMS (µm, each setup's zero removed) of each model of the loop, the first
    /// without effects.
    held_out_path_um: Vec<f64>,
    held_out_over_floor: f64,
}

pub fn run(args: &BenchArgs) -> Result<()> {
    match &args.which {
        Bench::Discovery(a) => discovery(a),
        Bench::Soak(a) => soak::run(a),
        Bench::Calibration(a) => calibration::run(a),
        Bench::Plan(a) => plan::run(a),
    }
}

fn discovery(a: &DiscoveryArgs) -> Result<()> {
    if a.machines == 0 || a.threads == 0 {
        return Err(bad_input(
            "--machines and --threads: expected at least 1".into(),
        ));
    }
    if let Some(i) = a.only {
        let o = machine(a.seed, i, true)?;
        println!("{}", serde_json::to_string_pretty(&o)?);
        return Ok(());
    }
    let next = AtomicUsize::new(0);
    let done = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..a.threads {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= a.machines {
                    break;
                }
                // a diagnosis that fails counts as a wrong answer, with its error
                let out = machine(a.seed, i, false).unwrap_or_else(|e| failed(a.seed, i, &e));
                if let Ok(mut d) = done.lock() {
                    d.push(out);
                    eprint!("\r  {} of {} machines", d.len(), a.machines);
                }
            });
        }
    });
    eprintln!();
    let mut all: Vec<Outcome> = done
        .into_inner()
        .map_err(|_| anyhow::anyhow!("a worker panicked"))?;
    all.sort_by_key(|o| o.machine);
    print_table(&all);
    if let Some(path) = &a.json {
        super::write_json(path, &serde_json::to_value(&all)?)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The kinds of machine the bench draws, each reported on its own line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
enum Class {
    /// Nothing hidden.
    Nothing,
    /// One or two effects of the library.
    Library,
    /// Lost motion (backlash), outside the library.
    LostMotion,
    /// A periodic error of one carrier's scale, 1-5 µm over a pitch of 10-200 mm, outside
    /// the library.
    Cyclic,
    /// All drives active (preload_elastic) and one rod 0.5-0.8x or 1.25-2x as stiff as the
    /// others.
    SoftRod,
    /// An instrument alignment 0.2-1x its default: down to where it hardly matters.
    SmallAlignment,
}

/// What a machine hides: its class and its hidden effects of the twin.
struct Hidden {
    class: Class,
    effects: Vec<EffectKind>,
}

fn log_uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    (rng.gen_range(lo.ln()..hi.ln())).exp()
}

/// The class of machine `k` (0..25) and its hidden effects.
fn hidden_of(k: u32, rng: &mut StdRng) -> Hidden {
    let library: Vec<EffectKind> = EffectKind::ALL
        .iter()
        .copied()
        .filter(|e| !e.outside_library())
        .collect();
    let pick = |rng: &mut StdRng| library[rng.gen_range(0..library.len())];
    let (class, effects) = match k {
        0..=5 => (Class::Nothing, Vec::new()),
        6..=13 => (Class::Library, vec![pick(rng)]),
        14..=15 => {
            let first = pick(rng);
            let mut second = pick(rng);
            while second == first {
                second = pick(rng);
            }
            (Class::Library, vec![first, second])
        }
        16..=17 => (Class::LostMotion, vec![EffectKind::Backlash]),
        18..=20 => (Class::Cyclic, Vec::new()),
        21..=22 => (Class::SoftRod, vec![EffectKind::PreloadElastic]),
        _ => (Class::SmallAlignment, vec![EffectKind::InstrumentAlignment]),
    };
    Hidden { class, effects }
}

/// A machine's hidden effects and conventions, drawn from `seed` and its index.
fn draw(seed: u64, i: usize) -> (TwinConfig, Hidden) {
    let mut rng = StdRng::seed_from_u64(seed.wrapping_mul(0x9e37_79b9).wrapping_add(i as u64));
    let k = rng.gen_range(0..25);
    let hidden = hidden_of(k, &mut rng);
    let noise: [f64; N_GROUPS] = std::array::from_fn(|_| log_uniform(&mut rng, 0.5, 3.0));
    let mut parts = [0.0; 3];
    while parts.iter().all(|p| *p == 0.0) {
        for p in &mut parts {
            *p = if rng.gen_bool(0.5) {
                rng.gen_range(5e-6..25e-6)
            } else {
                0.0
            };
        }
    }
    let (lo, hi) = if hidden.class == Class::SmallAlignment {
        (0.2, 1.0)
    } else {
        (0.3, 3.0)
    };
    let effects = hidden
        .effects
        .iter()
        .map(|e| (*e, e.default_magnitude() * log_uniform(&mut rng, lo, hi)))
        .collect();
    let mut stiffness = rpkm_core::elastic::Stiffness::default();
    if hidden.class == Class::SoftRod {
        let rod = rng.gen_range(0..4);
        stiffness.rod[rod] *= if rng.gen_bool(0.5) {
            rng.gen_range(0.5..0.8)
        } else {
            rng.gen_range(1.25..2.0)
        };
    }
    let cyclic = (hidden.class == Class::Cyclic).then(|| rpkm_twin::CyclicScale {
        carrier: rng.gen_range(0..4),
        amplitude_mm: rng.gen_range(1e-3..5e-3),
        pitch_mm: log_uniform(&mut rng, 10.0, 200.0),
        phase: rng.gen_range(0.0..std::f64::consts::TAU),
    });
    let config = TwinConfig {
        stiffness,
        cyclic,
        seed: rng.gen(),
        effects,
        length_sigma_mm: rng.gen_range(0.05..0.1),
        angle_sigma_rad: rng.gen_range(1e-4..3e-4),
        noise: Some(NoiseModel::default().scaled(&noise)),
        thermal: ThermalPhysics {
            rods_per_k: parts[0],
            frame_per_k: parts[1],
            scales_per_k: parts[2],
            ..Default::default()
        },
        ..Default::default()
    };
    (config, hidden)
}

/// Calibration and held-out campaigns of a twin, and the held-out noise floor (µm): the same
/// held-out poses measured without noise.
fn measure(config: &TwinConfig) -> Result<(Campaign, Campaign, f64)> {
    let run = |config: TwinConfig| -> Result<(Campaign, Campaign)> {
        let mut twin = Twin::new(config)?;
        let cal = twin.campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])?;
        Ok((cal, twin.validation(100)?))
    };
    let (cal, val) = run(config.clone())?;
    let (_, clean) = run(TwinConfig {
        noise: None,
        ..config.clone()
    })?;
    let floor = rpkm_twin::reading_error_rms_um(&val, &clean);
    Ok((cal, val, floor))
}

fn machine(seed: u64, i: usize, verbose: bool) -> Result<Outcome> {
    let (config, hidden) = draw(seed, i);
    if verbose {
        println!(
            "machine {i}: {:?} {:?}, {:?}",
            hidden.class,
            hidden_names(&hidden),
            config.thermal
        );
    }
    let (cal, val, floor) = measure(&config)?;
    let mut named: Vec<String> = Vec::new();
    // the held-out errors of each model of the loop: a named effect must never raise them
    let mut path: Vec<Vec<f64>> = Vec::new();
    let (kind, held) = loop {
        let boxed: Vec<Box<dyn Effect>> = named
            .iter()
            .map(|n| effects::by_name(n))
            .collect::<Result<_, _>>()?;
        let refs: Vec<&dyn Effect> = boxed.iter().map(std::convert::AsRef::as_ref).collect();
        // the bench runs machines in parallel (--threads): each diagnosis on one thread
        let opts = Options {
            threads: 1,
            ..Options::default()
        };
        let d = diagnose::diagnose(&cal, Some(&val), &refs, &opts)?;
        if verbose {
            println!("with {named:?}: {}", crate::words::verdict(&d));
        }
        path.push(d.baseline.val_errors.clone());
        match d.missing_effect {
            Some(e) if !named.contains(&e) && named.len() < 3 => {
                named.push(e);
                named.extend(d.together_with.filter(|t| !named.contains(t)));
            }
            _ => break (d.verdict_kind, d.baseline.val_rms_um.unwrap_or(f64::NAN)),
        }
    };
    // each step of the loop judged as the diagnosis judges a candidate
    let steps: Vec<Prediction> = path
        .windows(2)
        .filter_map(|w| Prediction::of(&w[0], &w[1]))
        .collect();
    let judged = Judged {
        named: &named,
        kind,
        held_over_floor: held / floor,
    };
    Ok(Outcome {
        machine: i,
        class: hidden.class,
        hidden: hidden_names(&hidden),
        correct: judged.correct(&hidden),
        largest_rise: steps
            .iter()
            .map(|p| p.rms_after / p.rms_before - 1.0)
            .fold(0.0, f64::max),
        largest_rise_se: steps
            .iter()
            .map(|p| (p.rms_after - p.rms_before) / p.standard_error)
            .fold(0.0, f64::max),
        held_out_path_um: path.iter().map(|e| calib::rms(e) * 1e3).collect(),
        final_verdict: serde_json::to_value(kind)?
            .as_str()
            .unwrap_or_default()
            .to_owned(),
        named,
        held_out_over_floor: held / floor,
    })
}

/// The hidden effects by name: the twin's kinds, and the conventions outside the library.
fn hidden_names(hidden: &Hidden) -> Vec<String> {
    let mut out: Vec<String> = hidden
        .effects
        .iter()
        .map(|e| e.as_str().to_owned())
        .collect();
    match hidden.class {
        Class::Cyclic => out.push("cyclic_scale".to_owned()),
        Class::SoftRod => out.push("soft_rod".to_owned()),
        _ => {}
    }
    out
}

/// What the loop ended with.
struct Judged<'a> {
    named: &'a [String],
    kind: VerdictKind,
    held_over_floor: f64,
}

/// A small alignment counts as found when the held-out RMS without it is within this of the
/// floor: below it the alignment hardly matters.
const SMALL_ENOUGH: f64 = 1.3;

impl Judged<'_> {
    /// Whether the loop named exactly the hidden library effects and ended as it should:
    /// `nothing_missing`, or `unexplained_structure` for an effect outside the library (a
    /// soft rod may end either way, its preload's effect absorbing the rest; an alignment too
    /// small to matter may go unnamed at the floor).
    fn correct(&self, hidden: &Hidden) -> bool {
        let mut named: Vec<&str> = self.named.iter().map(String::as_str).collect();
        named.sort_unstable();
        let mut want: Vec<&str> = hidden
            .effects
            .iter()
            .filter(|e| **e != EffectKind::Backlash)
            .map(|e| e.as_str())
            .collect();
        want.sort_unstable();
        let ends = |k: VerdictKind| self.kind == k;
        match hidden.class {
            Class::LostMotion | Class::Cyclic => {
                named.is_empty() && ends(VerdictKind::UnexplainedStructure)
            }
            Class::SoftRod => {
                named == want
                    && (ends(VerdictKind::NothingMissing)
                        || ends(VerdictKind::UnexplainedStructure))
            }
            Class::SmallAlignment if named.is_empty() => {
                ends(VerdictKind::NothingMissing) && self.held_over_floor <= SMALL_ENOUGH
            }
            _ => named == want && ends(VerdictKind::NothingMissing),
        }
    }
}

/// The outcome of a machine whose loop ended in an error.
fn failed(seed: u64, i: usize, e: &anyhow::Error) -> Outcome {
    let (_, hidden) = draw(seed, i);
    Outcome {
        machine: i,
        class: hidden.class,
        hidden: hidden_names(&hidden),
        named: Vec::new(),
        final_verdict: format!("error: {}", super::error_chain(e)),
        correct: false,
        largest_rise: 0.0,
        largest_rise_se: 0.0,
        held_out_path_um: Vec::new(),
        held_out_over_floor: f64::NAN,
    }
}

/// The loops whose held-out error rose at a step: beyond twice its standard error (what a
/// diagnosis calls predicting worse), and within it.
fn print_rises(all: &[Outcome]) {
    let rose: Vec<&Outcome> = all.iter().filter(|o| o.largest_rise > 0.0).collect();
    let worse = rose.iter().filter(|o| o.largest_rise_se > 2.0).count();
    let largest = |f: fn(&Outcome) -> f64| rose.iter().map(|o| f(o)).fold(0.0, f64::max);
    println!(
        "machines where a named effect raised the held-out RMS: {worse} by more than twice \
         its standard error; {} within it (the largest {:.2} %, {:.2} standard errors)",
        rose.len() - worse,
        100.0 * largest(|o| o.largest_rise),
        largest(|o| o.largest_rise_se)
    );
}

fn print_table(all: &[Outcome]) {
    let label = |v: &[String]| {
        if v.is_empty() {
            "-".to_owned()
        } else {
            v.join("+")
        }
    };
    let mut matrix: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for o in all {
        *matrix
            .entry(label(&o.hidden))
            .or_default()
            .entry(format!("{} [{}]", label(&o.named), o.final_verdict))
            .or_default() += 1;
    }
    println!("hidden -> named [final verdict]: machines");
    for (hidden, row) in &matrix {
        let cells: Vec<String> = row.iter().map(|(k, n)| format!("{k}: {n}")).collect();
        println!("  {hidden:<40} {}", cells.join(", "));
    }
    println!("\nper class: correct of machines");
    let mut classes: BTreeMap<Class, (usize, usize)> = BTreeMap::new();
    for o in all {
        let e = classes.entry(o.class).or_default();
        e.0 += usize::from(o.correct);
        e.1 += 1;
    }
    for (class, (ok, n)) in &classes {
        println!("  {:<16} {ok} of {n}", format!("{class:?}"));
    }
    print_rises(all);
    let correct = all.iter().filter(|o| o.correct).count();
    let nothing: Vec<&Outcome> = all.iter().filter(|o| o.hidden.is_empty()).collect();
    let alarms = nothing.iter().filter(|o| !o.correct).count();
    let mut ratio: Vec<f64> = all
        .iter()
        .map(|o| o.held_out_over_floor)
        .filter(|r| r.is_finite())
        .collect();
    ratio.sort_by(f64::total_cmp);
    let q = |f: f64| {
        ratio
            .get(rpkm_core::convert::round_count(
                (ratio.len() as f64 - 1.0) * f,
            ))
            .copied()
    };
    println!(
        "\ncorrect: {correct} of {} ({:.1} %)",
        all.len(),
        100.0 * correct as f64 / all.len().max(1) as f64
    );
    println!(
        "false alarms on machines with nothing hidden: {alarms} of {} ({:.1} %)",
        nothing.len(),
        100.0 * alarms as f64 / nothing.len().max(1) as f64
    );
    if let (Some(m), Some(p90)) = (q(0.5), q(0.9)) {
        println!(
            "held-out RMS after the loop / true floor: median {m:.3}, 90th percentile {p90:.3}"
        );
    }
}
