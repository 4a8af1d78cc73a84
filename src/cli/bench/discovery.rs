//! `rpkm bench discovery`: the discovery loop on random machines, judged against what each
//! hides, and the table of what it named.

use super::machines::{self, Class, Hidden, Machine, Measured, Named};
use super::DiscoveryArgs;
use crate::cli::bad_input;
use crate::cli::effect_stages::offered;
use anyhow::{Context, Result};
use rpkm_core::diagnose::{self, DiagnosisOptions, ModelDiagnosis, Prediction, VerdictKind};
use rpkm_core::effects::{self, Effect, Family};
use rpkm_core::units::um_from_mm;
use rpkm_nodes::effects_file::{self, EffectsFile};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// What one machine was and what the loop said.
#[derive(Clone, Debug, serde::Serialize)]
struct Outcome {
    machine: usize,
    class: Class,
    hidden: Vec<String>,
    named: Vec<String>,
    /// The last model as fitted: a family's parts, an effect's refinement
    /// (`preload_elastic:rod3`).
    fitted_as: Vec<String>,
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
    /// The last diagnosis's held-out RMS with each setup's zero removed over the truth's
    /// floor of the same (the realised noise, each setup's mean removed).
    held_out_relative_over_floor: f64,
    /// `nothing_missing` while that ratio exceeds 1 + 2 SE (SE = 1/√(2(n − g))): a verdict
    /// the held-out data contradict.
    nothing_missing_above_floor: bool,
    /// The last diagnosis's held-out judge: P(the errors this far above the model's floor)
    /// under a right model. Uniform on machines with nothing hidden where the judge is honest.
    held_out_p: f64,
    /// The hidden effects themselves fitted on the calibration and diagnosed, where the class
    /// lets them be written as a model ([`machines::truth_model`]).
    truth: Option<TruthFit>,
}

/// What a diagnosis says of the hidden effects themselves (the truth's parts pinned, no
/// settle): whether the campaigns let even the truth end `nothing_missing` at the floor.
#[derive(Clone, Debug, serde::Serialize)]
struct TruthFit {
    fitted_as: Vec<String>,
    verdict: String,
    /// Its held-out RMS with each setup's zero removed over the truth's floor of the same.
    held_out_relative_over_floor: f64,
    /// That ratio above 1 + 2 SE.
    above_floor: bool,
    held_out_p: f64,
}

pub(super) fn run(a: &DiscoveryArgs) -> Result<()> {
    if a.machines == 0 || a.threads == 0 {
        return Err(bad_input(
            "--machines and --threads: expected at least 1".into(),
        ));
    }
    let series = Series {
        seed: a.seed,
        class: a.class,
    };
    if let Some(i) = a.only {
        let shown = Shown::Steps {
            write: a.write.as_deref(),
        };
        let o = machine(series, i, shown)?;
        println!("{}", serde_json::to_string_pretty(&o)?);
        return Ok(());
    }
    // machine i of a seed is the same machine with or without --class
    let indices: Vec<usize> = match a.class {
        Some(class) if !machines::on_demand(class) => (0..)
            .filter(|&i| machines::draw(a.seed, i, None).hidden.class == class)
            .take(a.machines)
            .collect(),
        _ => (0..a.machines).collect(),
    };
    let next = AtomicUsize::new(0);
    let done = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..a.threads {
            s.spawn(|| {
                while let Some(&i) = indices.get(next.fetch_add(1, Ordering::Relaxed)) {
                    // a diagnosis that fails counts as a wrong answer, with its error
                    let out = machine(series, i, Shown::Outcome)
                        .unwrap_or_else(|e| failed(series, i, &e));
                    if let Ok(mut d) = done.lock() {
                        d.push(out);
                        eprint!("\r  {} of {} machines", d.len(), a.machines);
                    }
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
        crate::cli::write_json(path, &serde_json::to_value(&all)?)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The loop a user runs: diagnose, add the families of the model the diagnosis names
/// (`--effects thermal,thermal_lag` where it found `thermal:frame` with `thermal_lag:frame`:
/// the next diagnosis settles the parts with what is then in the model, where the parts
/// found first may have stood in for an effect not yet added), diagnose again, until it
/// names no family new.
struct Loop<'a> {
    measured: &'a Measured,
    file: Option<&'a EffectsFile>,
    shown: Shown<'a>,
}

impl Loop<'_> {
    /// The diagnoses of the loop, the first without effects, and the effects named.
    fn run(&self) -> Result<(Vec<ModelDiagnosis>, Vec<String>)> {
        let (mut named, mut all): (Vec<String>, Vec<ModelDiagnosis>) = (Vec::new(), Vec::new());
        loop {
            let d = diagnosis(self.measured, &named, self.file)?;
            if matches!(self.shown, Shown::Steps { .. }) {
                println!("with {named:?}: {}", rpkm_nodes::words::verdict(&d));
            }
            let new: Vec<String> = d
                .missing_effects
                .iter()
                .map(|e| effects::family_of(e).to_owned())
                .filter(|e| !named.contains(e))
                .collect();
            all.push(d);
            if new.is_empty() || named.len() >= 4 {
                return Ok((all, named));
            }
            named.extend(new);
        }
    }
}

/// The diagnosis of a machine's campaigns with the effects `names` in the model, trying the
/// library's and those `file` offers: each on one thread (the bench runs machines in
/// parallel, `--threads`).
fn diagnosis(
    measured: &Measured,
    names: &[String],
    file: Option<&EffectsFile>,
) -> Result<ModelDiagnosis> {
    let boxed = effects_file::parse_list(&names.join(","), file).map_err(|e| anyhow::anyhow!(e))?;
    let refs: Vec<&dyn Effect> = boxed.iter().map(AsRef::as_ref).collect();
    let opts = DiagnosisOptions {
        threads: 1,
        ..DiagnosisOptions::default()
    };
    let (cal, val) = (&measured.cal, &measured.val);
    Ok(diagnose::diagnose_among(
        cal,
        Some(val),
        &refs,
        &offered(file, &refs),
        &opts,
    )?)
}

/// A series of machines: its seed, and the class drawn on demand (`--class`).
#[derive(Clone, Copy)]
struct Series {
    seed: u64,
    class: Option<Class>,
}

impl Series {
    /// Its machine `i`.
    fn machine(self, i: usize) -> Machine {
        machines::draw(self.seed, i, self.class)
    }
}

/// What a machine's run shows beside its outcome: nothing (a series), or (`--only`) the
/// machine and each step of its loop, its files written under `write` where given.
#[derive(Clone, Copy)]
enum Shown<'a> {
    Outcome,
    Steps { write: Option<&'a Path> },
}

fn machine(series: Series, i: usize, shown: Shown) -> Result<Outcome> {
    let m = series.machine(i);
    if let Shown::Steps { .. } = shown {
        println!(
            "machine {i}: {:?} {:?}, {:?}, {:?}, {:?}",
            m.hidden.class,
            machines::hidden_names(&m.hidden),
            m.config.thermal,
            m.config.drift,
            m.config.cyclic,
        );
    }
    let measured = machines::measure(&m)?;
    let mut columns = measured.cal.covariate_names.clone();
    columns.extend(measured.val.covariate_names.iter().cloned());
    let file = machines::offered(&m, &columns)?;
    if let Shown::Steps { write: Some(dir) } = shown {
        write_machine(dir, &m, &measured)?;
    }
    let (diagnoses, named) = Loop {
        measured: &measured,
        file: file.as_ref(),
        shown,
    }
    .run()?;
    let mut out = outcome(i, &m, &measured, &diagnoses, named);
    if let Some(names) = machines::truth_model(&m) {
        out.truth = Some(truth_fit(&measured, &names)?);
    }
    Ok(out)
}

/// The diagnosis of the model `names` (the hidden effects as [`machines::truth_model`]
/// writes them) on the machine's campaigns.
fn truth_fit(measured: &Measured, names: &[String]) -> Result<TruthFit> {
    let d = diagnosis(measured, names, None)?;
    let relative = relative_over_floor(measured, &d);
    Ok(TruthFit {
        fitted_as: d.model_effects.clone(),
        verdict: verdict_name(d.verdict_kind),
        held_out_relative_over_floor: relative,
        above_floor: relative > 1.0 + 2.0 * floor_se(measured),
        held_out_p: d.held_out.as_ref().map_or(f64::NAN, |h| h.p_value),
    })
}

/// A diagnosis's held-out RMS with each setup's zero removed over the truth's floor of the
/// same.
fn relative_over_floor(measured: &Measured, d: &ModelDiagnosis) -> f64 {
    d.held_out.as_ref().map_or(f64::NAN, |h| {
        um_from_mm(h.rms_relative()) / measured.floor_relative_um
    })
}

/// The standard error of that ratio under noise alone, 1/√(2(n − g)).
fn floor_se(measured: &Measured) -> f64 {
    1.0 / (2.0 * measured.relative_dof.max(1) as f64).sqrt()
}

/// A verdict's name as the JSON writes it (`nothing_missing`).
fn verdict_name(kind: VerdictKind) -> String {
    serde_json::to_value(kind)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default()
}

/// A machine's campaigns, offered effects and truth as files under `dir` (`--write`).
fn write_machine(dir: &Path, m: &Machine, measured: &Measured) -> Result<()> {
    let put = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    put("cal.csv", &measured.cal.to_csv())?;
    put("val.csv", &measured.val.to_csv())?;
    let offered = machines::offered_text(m)?;
    if !offered.is_empty() {
        put("effects.yaml", &offered)?;
    }
    put(
        "machine.txt",
        &format!(
            "hides: {:?}\nheld-out floor: {:.3} µm ({:.3} µm with each setup's zero removed)\n\n{:#?}\n",
            machines::hidden_names(&m.hidden),
            measured.floor_um,
            measured.floor_relative_um,
            m.config
        ),
    )?;
    println!("wrote {}", dir.display());
    Ok(())
}

/// What a machine's loop said, judged against what it hides.
fn outcome(
    i: usize,
    m: &Machine,
    measured: &Measured,
    diagnoses: &[ModelDiagnosis],
    named: Vec<String>,
) -> Outcome {
    let last = &diagnoses[diagnoses.len() - 1];
    let kind = last.verdict_kind;
    let held_over_floor = last.baseline.val_rms.map_or(f64::NAN, um_from_mm) / measured.floor_um;
    let relative = relative_over_floor(measured, last);
    let se = floor_se(measured);
    // each step of the loop judged as the diagnosis judges a candidate
    let steps: Vec<Prediction> = diagnoses
        .windows(2)
        .filter_map(|w| {
            let (before, after) = (
                w[0].baseline.held_out.as_ref()?,
                w[1].baseline.held_out.as_ref()?,
            );
            Prediction::of(&before.errors.relative, &after.errors.relative)
        })
        .collect();
    let judged = Judged {
        named: &named,
        kind,
        held_over_floor,
        own_rod: own_rod_right(m, &last.model_effects),
    };
    Outcome {
        machine: i,
        class: m.hidden.class,
        hidden: machines::hidden_names(&m.hidden),
        correct: judged.correct(&m.hidden),
        largest_rise: steps
            .iter()
            .map(|p| p.rms_after / p.rms_before - 1.0)
            .fold(0.0, f64::max),
        largest_rise_se: steps
            .iter()
            .map(|p| (p.rms_after - p.rms_before) / p.standard_error)
            .fold(0.0, f64::max),
        held_out_path_um: diagnoses
            .iter()
            .map(|d| d.baseline.val_rms_relative.map_or(f64::NAN, um_from_mm))
            .collect(),
        final_verdict: verdict_name(kind),
        named,
        fitted_as: last.model_effects.clone(),
        held_out_over_floor: held_over_floor,
        held_out_relative_over_floor: relative,
        nothing_missing_above_floor: kind == VerdictKind::NothingMissing
            && relative > 1.0 + 2.0 * se,
        held_out_p: last.held_out.as_ref().map_or(f64::NAN, |h| h.p_value),
        truth: None,
    }
}

/// What the loop ended with.
struct Judged<'a> {
    named: &'a [String],
    kind: VerdictKind,
    held_over_floor: f64,
    /// Whether the model as fitted gives the rod of another stiffness, where the machine has
    /// one, its own compliance (`preload_elastic:rodN`), and no other rod one.
    own_rod: bool,
}

/// See [`Judged::own_rod`]: each rod of another stiffness, and each refinement of the
/// preload in the model as fitted, by the rod it gives a compliance of its own (its place
/// among the preload's refinements, which go in rod order).
fn own_rod_right(m: &Machine, fitted_as: &[String]) -> bool {
    let default = rpkm_core::elastic::DEFAULT_ROD_STIFFNESS_N_PER_MM;
    let want: Vec<Option<usize>> = (m.config.stiffness.rod.iter())
        .enumerate()
        .filter(|(_, k)| (**k / default - 1.0).abs() > 1e-9)
        .map(|(r, _)| Some(r))
        .collect();
    let refinements = effects::PreloadElastic::default().refinements();
    let have: Vec<Option<usize>> = fitted_as
        .iter()
        .filter(|e| {
            Family::of(e) == Some(Family::PreloadElastic) && effects::family_of(e) != e.as_str()
        })
        .map(|e| refinements.iter().position(|r| r.name() == e))
        .collect();
    have.len() == want.len() && want.iter().all(|w| have.contains(w))
}

/// A small alignment (or a slow drift) counts as found when the held-out RMS without it is
/// within this of the floor: below it, it hardly matters.
const SMALL_ENOUGH: f64 = 1.3;

impl Judged<'_> {
    /// Whether the loop named exactly the hidden effects it can name and ended as it
    /// should: `nothing_missing` (a soft rod too, with its own compliance and no other rod
    /// given one: the preload's refinement), or `unexplained_structure` for an effect
    /// outside the library that is not offered (guides at two temperatures may end either
    /// way, how the frame between them moves being beyond the library; an alignment or a
    /// drift too small to matter may go unnamed at the floor).
    fn correct(&self, hidden: &Hidden) -> bool {
        let named: Vec<Named> = self.named.iter().map(|n| Named::of(n)).collect();
        let want = machines::nameable(hidden);
        let ends = |k: VerdictKind| self.kind == k;
        let at_floor = ends(VerdictKind::NothingMissing) && self.held_over_floor <= SMALL_ENOUGH;
        match hidden.class {
            Class::LostMotion | Class::Cyclic => {
                named.is_empty() && ends(VerdictKind::UnexplainedStructure)
            }
            Class::Gradient => {
                same_effects(&named, &want)
                    && (ends(VerdictKind::NothingMissing)
                        || ends(VerdictKind::UnexplainedStructure))
            }
            Class::SmallAlignment | Class::TrackerDrift if named.is_empty() => at_floor,
            Class::ThermometerLag if named == [Named::Family(Family::Thermal)] => at_floor,
            _ => same_effects(&named, &want) && ends(VerdictKind::NothingMissing) && self.own_rod,
        }
    }
}

/// Whether `a` and `b` hold the same effects as often, in any order.
fn same_effects(a: &[Named], b: &[Named]) -> bool {
    let count = |v: &[Named], e: &Named| v.iter().filter(|x| *x == e).count();
    a.len() == b.len() && a.iter().all(|e| count(a, e) == count(b, e))
}

/// The outcome of a machine whose loop ended in an error.
fn failed(series: Series, i: usize, e: &anyhow::Error) -> Outcome {
    let m = series.machine(i);
    Outcome {
        machine: i,
        class: m.hidden.class,
        hidden: machines::hidden_names(&m.hidden),
        named: Vec::new(),
        fitted_as: Vec::new(),
        final_verdict: format!("error: {}", crate::cli::error_chain(e)),
        correct: false,
        largest_rise: 0.0,
        largest_rise_se: 0.0,
        held_out_path_um: Vec::new(),
        held_out_over_floor: f64::NAN,
        held_out_relative_over_floor: f64::NAN,
        nothing_missing_above_floor: false,
        held_out_p: f64::NAN,
        truth: None,
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
    print_totals(all);
}

/// The share right, the false alarms, the verdicts the held-out data contradict, and how
/// far the loop ends from the floor.
fn print_totals(all: &[Outcome]) {
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
    let above: Vec<String> = all
        .iter()
        .filter(|o| o.nothing_missing_above_floor)
        .map(|o| {
            format!(
                "{} ({:?}, {:.2})",
                o.machine, o.class, o.held_out_relative_over_floor
            )
        })
        .collect();
    println!(
        "nothing_missing with the held-out RMS (zero removed) above its true floor by more \
         than 2 SE: {} of {}{}",
        above.len(),
        all.len(),
        if above.is_empty() {
            String::new()
        } else {
            format!(": machines {}", above.join(", "))
        }
    );
    print_truth(all);
    print_judge_tails(&nothing);
    if let (Some(m), Some(p90)) = (q(0.5), q(0.9)) {
        println!(
            "held-out RMS after the loop / true floor: median {m:.3}, 90th percentile {p90:.3}"
        );
    }
}

/// How often the held-out judge's p-value falls in each tail on machines with nothing hidden,
/// against what an honest judge gives (its p-values uniform there).
fn print_judge_tails(nothing: &[&Outcome]) {
    let p: Vec<f64> = nothing
        .iter()
        .map(|o| o.held_out_p)
        .filter(|p| p.is_finite())
        .collect();
    let n = p.len() as f64;
    let count = |f: &dyn Fn(f64) -> bool| p.iter().filter(|&&x| f(x)).count();
    println!(
        "held-out judge on machines with nothing hidden: p < 0.05 on {} of {} ({:.1} due), \
         p > 0.95 on {} ({:.1} due)",
        count(&|x| x < 0.05),
        p.len(),
        0.05 * n,
        count(&|x| x > 0.95),
        0.05 * n
    );
}

/// Where the hidden effects themselves were fitted ([`TruthFit`]): on how many machines the
/// truth ends `nothing_missing`, and at the floor; how often the loop is right where it
/// does (what these campaigns let any model reach); and the loop's wrong answers on machines
/// where even the truth does not.
fn print_truth(all: &[Outcome]) {
    let fitted: Vec<(&Outcome, &TruthFit)> = all
        .iter()
        .filter_map(|o| o.truth.as_ref().map(|t| (o, t)))
        .collect();
    if fitted.is_empty() {
        return;
    }
    let passes = |t: &TruthFit| t.verdict == verdict_name(VerdictKind::NothingMissing);
    let at_floor = |t: &TruthFit| passes(t) && !t.above_floor;
    let wrong: Vec<&(&Outcome, &TruthFit)> = fitted.iter().filter(|(o, _)| !o.correct).collect();
    let list = |v: Vec<String>| {
        if v.is_empty() {
            String::new()
        } else {
            format!(": machines {}", v.join(", "))
        }
    };
    let reachable = || fitted.iter().filter(|(_, t)| at_floor(t));
    println!(
        "the hidden effects themselves, fitted and diagnosed (their parts pinned): \
         nothing_missing on {} of {}, of those at the floor (within 2 SE) {}",
        fitted.iter().filter(|(_, t)| passes(t)).count(),
        fitted.len(),
        reachable().count(),
    );
    println!(
        "  where the truth itself ends nothing_missing at the floor, the loop is right on {} of {}",
        reachable().filter(|(o, _)| o.correct).count(),
        reachable().count()
    );
    println!(
        "  of the {} the loop got wrong, the truth itself not nothing_missing at the floor on {}{}",
        wrong.len(),
        wrong.iter().filter(|(_, t)| !at_floor(t)).count(),
        list(
            wrong
                .iter()
                .filter(|(_, t)| !at_floor(t))
                .map(|(o, t)| format!(
                    "{} ({}, {:.2})",
                    o.machine, t.verdict, t.held_out_relative_over_floor
                ))
                .collect()
        )
    );
}
