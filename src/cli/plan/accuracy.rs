//! `rpkm plan` for the TCP (the default criterion): the plan that lowers the expected
//! held-out RMS most, what it buys against as many random poses, per budget; and where the
//! instruments asked for can buy nothing, which others would.

use super::args::PlanArgs;
use super::determine::setups_json;
use super::output::{write_outputs, Drives};
use rpkm_core::campaign::Instrument;
use rpkm_core::plan::{
    self, own_error as own, AccuracyPlanner, CandidateSetup, DeterminationPlan, Forecast, Start,
    TargetForecast, Unknowns, WORTH,
};
use rpkm_core::units::um_from_mm;
use serde_json::json;

/// Random designs the plan is compared with (the median of their expected RMS).
const RANDOM_DRAWS: usize = 25;
/// Seed of the random designs: the same comparison every run.
const RANDOM_SEED: u64 = 0x5eed_0037;
/// Instruments a plan may use, in the order they are suggested on a tie.
const ALL: [Instrument; 5] = [
    Instrument::Lt,
    Instrument::Kgm,
    Instrument::Dbb,
    Instrument::LiPsi,
    Instrument::SelfCal,
];

/// One budget's plan and what it buys.
struct Budgeted {
    budget: usize,
    plan: DeterminationPlan,
    forecast: Forecast,
    random_mm: f64,
}

/// The plan for each budget of `args`, printed; PLAN.csv and the JSON of the last.
pub fn run(
    args: &PlanArgs,
    (start, unknowns): (&Start, &Unknowns),
    (instruments, drives): (&[Instrument], &Drives),
    (evaluation, where_words): (&TargetForecast, &str),
) -> anyhow::Result<()> {
    let setups = plan::candidates(instruments)?;
    let planner = AccuracyPlanner::new(start, unknowns, &setups, evaluation)?;
    let mut all = Vec::with_capacity(args.budget.len());
    for &budget in &args.budget {
        let (p, forecast) = planner.plan(budget)?;
        let random_setup = p.setups.first().map_or(&setups[0], |s| &s.setup);
        let random_mm = planner.random((random_setup, budget), (RANDOM_DRAWS, RANDOM_SEED))?;
        all.push(Budgeted {
            budget,
            plan: p,
            forecast,
            random_mm,
        });
    }
    let Some(last) = all.last() else {
        return Ok(());
    };
    print_plan(last, where_words);
    if all.len() > 1 {
        print_budgets(&all);
    }
    let f = last.forecast;
    if !f.pays() {
        print_nothing_to_gain(start, unknowns, (instruments, last.budget), evaluation)?;
    }
    let design = plan::measured_in(last.plan.design(), &drives.mode);
    write_outputs(
        args,
        (&design, drives),
        &comments(last, where_words),
        || {
            json!({
                "kind": "tcp",
                "held_out": where_words,
                "budget": last.budget,
                "now_um": um_from_mm(f.now_mm),
                "after_um": um_from_mm(f.after_mm),
                "random_um": um_from_mm(last.random_mm),
                "floor_um": um_from_mm(f.floor_mm),
            "own_now_um": um_from_mm(own(f.now_mm, f.floor_mm)),
            "own_after_um": um_from_mm(own(f.after_mm, f.floor_mm)),
            "own_random_um": um_from_mm(own(last.random_mm, f.floor_mm)),
            "pays": f.pays(),
                "budgets": all.iter().map(|b| json!({
                    "budget": b.budget,
                    "poses": b.plan.design().len(),
                    "after_um": um_from_mm(b.forecast.after_mm),
                    "random_um": um_from_mm(b.random_mm),
                })).collect::<Vec<_>>(),
                "before": last.plan.before,
                "after": last.plan.after(),
                "setups": setups_json(&last.plan),
            })
        },
    )
}

fn print_plan(b: &Budgeted, where_words: &str) {
    let f = b.forecast;
    let line = |what: &str, rms: f64| {
        println!(
            "  {what:<26} {:>8.2} µm {:>13.2} µm",
            um_from_mm(rms),
            um_from_mm(own(rms, f.floor_mm))
        );
    };
    println!("expected held-out RMS ({where_words}, each setup's zero removed):");
    println!("  {:<26} {:>11} {:>16}", "", "held-out", "the TCP's own");
    line("now", f.now_mm);
    println!("\nplan of {} poses:", b.budget);
    for s in &b.plan.setups {
        println!("  {}", super::output::setup_line(s));
    }
    println!();
    line("after the plan", f.after_mm);
    line(&format!("{} random poses instead", b.budget), b.random_mm);
    println!(
        "  {:<26} {:>8.2} µm   (the floor: the tracker's own noise, zero removed)",
        "noise alone",
        um_from_mm(f.floor_mm)
    );
    println!(
        "  parameter combinations determined better than their tolerance: {} of {} now, {} after",
        b.plan.before.determined,
        b.plan.before.of,
        b.plan.after().determined
    );
    println!("\n{}", buys_words(b));
}

/// What the plan buys, in words.
fn buys_words(b: &Budgeted) -> String {
    let f = b.forecast;
    let um = |v: f64| um_from_mm(own(v, f.floor_mm));
    let (now, after, random) = (um(f.now_mm), um(f.after_mm), um(b.random_mm));
    if !f.pays() {
        return format!(
            "the plan buys nothing: the TCP's own error would stay at {after:.2} µm (now \
             {now:.2} µm, less than {:.0} % lower), under the held-out readings' noise of \
             {:.2} µm",
            WORTH * 100.0,
            um_from_mm(f.floor_mm)
        );
    }
    let versus = if after <= random {
        format!("{} random poses: {random:.2} µm", b.budget)
    } else {
        format!(
            "{} random poses would do better, {random:.2} um: the plan rests on the model",
            b.budget
        )
    };
    format!(
        "the plan lowers the TCP's own error from {now:.2} to {after:.2} µm ({versus}); the \
         held-out RMS from {:.2} to {:.2} µm",
        um_from_mm(f.now_mm),
        um_from_mm(f.after_mm)
    )
}

fn print_budgets(all: &[Budgeted]) {
    println!("\nby budget (expected held-out RMS; the TCP's own error):");
    println!(
        "  {:>6} {:>24} {:>24}",
        "poses", "after the plan", "random poses"
    );
    for b in all {
        let floor = b.forecast.floor_mm;
        println!(
            "  {:>6} {:>10.2} µm ({:>6.2} µm) {:>10.2} µm ({:>6.2} µm)",
            b.budget,
            um_from_mm(b.forecast.after_mm),
            um_from_mm(own(b.forecast.after_mm, floor)),
            um_from_mm(b.random_mm),
            um_from_mm(own(b.random_mm, floor))
        );
    }
}

/// Where these instruments buy nothing: the other instruments' plans of the same budget,
/// those that would buy something named best first.
fn print_nothing_to_gain(
    start: &Start,
    unknowns: &Unknowns,
    (instruments, budget): (&[Instrument], usize),
    evaluation: &TargetForecast,
) -> anyhow::Result<()> {
    let names: Vec<&str> = instruments
        .iter()
        .map(|i| super::output::spelling(*i))
        .collect();
    let mut better: Vec<(f64, Instrument)> = Vec::new();
    for other in ALL.into_iter().filter(|i| !instruments.contains(i)) {
        let setups: Vec<CandidateSetup> = plan::candidates(&[other])?;
        let planner = AccuracyPlanner::new(start, unknowns, &setups, evaluation)?;
        let (_, f) = planner.plan(budget)?;
        if f.pays() {
            better.push((own(f.after_mm, f.floor_mm), other));
        }
    }
    better.sort_by(|a, b| a.0.total_cmp(&b.0));
    if better.is_empty() {
        println!(
            "nothing to gain with {}, nor with any other instrument in {budget} poses: try \
             more poses (--budget), or another model (rpkm diagnose: an effect the model lacks)",
            names.join(", ")
        );
        return Ok(());
    }
    let tries: Vec<String> = better
        .iter()
        .map(|(mm, i)| {
            format!(
                "--instruments {} (the TCP's own error {:.2} µm)",
                super::output::spelling(*i),
                um_from_mm(*mm)
            )
        })
        .collect();
    println!(
        "nothing to gain with {} in {budget} poses; try {}",
        names.join(", "),
        tries.join(", or ")
    );
    Ok(())
}

fn comments(b: &Budgeted, where_words: &str) -> Vec<String> {
    let f = b.forecast;
    let mut out = vec![
        "rpkm plan: x, y are target TCP positions (mm), nothing measured yet".to_owned(),
        format!(
            "expected held-out RMS ({where_words}, each setup's zero removed): now {:.2} µm, \
             after the plan {:.2} µm, {} random poses {:.2} µm, noise floor {:.2} µm",
            um_from_mm(f.now_mm),
            um_from_mm(f.after_mm),
            b.budget,
            um_from_mm(b.random_mm),
            um_from_mm(f.floor_mm)
        ),
    ];
    for s in &b.plan.setups {
        let back = if s.setup.return_pose().is_some() {
            ", its last pose the return to its reset (drift check)"
        } else {
            ""
        };
        out.push(format!(
            "setup {} ({}, {} poses{back}): then {:.2} µm",
            s.setup.id,
            s.setup.instrument.as_str(),
            s.poses,
            um_from_mm(s.expected_mm.unwrap_or(f64::NAN))
        ));
    }
    out
}
