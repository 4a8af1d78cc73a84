//! `rpkm plan` for the TCP (the default criterion): the plan that lowers the expected
//! held-out RMS most, what it buys against as many random poses, per budget; and where the
//! instruments asked for can buy nothing, which others would.

use super::args::PlanArgs;
use super::determine::setups_json;
use super::output::{write_outputs, Drives};
use rpkm_core::campaign::Instrument;
use rpkm_core::plan::{
    self, AccuracyPlanner, CandidateSetup, DeterminationPlan, Evaluation, Forecast, Start, Unknowns,
};
use serde_json::json;

/// Random designs the plan is compared with (the median of their expected RMS).
const RANDOM_DRAWS: usize = 25;
/// Seed of the random designs: the same comparison every run.
const RANDOM_SEED: u64 = 0x5eed_0037;
/// A plan that lowers the expected held-out RMS by less than this share buys nothing.
const WORTH: f64 = 0.02;
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
    (evaluation, where_words): (&Evaluation, &str),
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
    if f.now_mm - f.after_mm < WORTH * f.now_mm {
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
                "now_um": f.now_mm * 1e3,
                "after_um": f.after_mm * 1e3,
                "random_um": last.random_mm * 1e3,
                "floor_um": f.floor_mm * 1e3,
                "budgets": all.iter().map(|b| json!({
                    "budget": b.budget,
                    "poses": b.plan.design().len(),
                    "after_um": b.forecast.after_mm * 1e3,
                    "random_um": b.random_mm * 1e3,
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
    println!("expected held-out RMS ({where_words}, each setup's zero removed):");
    println!(
        "  now                     {:>6.2} um   ({} of {} parameter combinations determined)",
        f.now_mm * 1e3,
        b.plan.before.determined,
        b.plan.before.of
    );
    println!("\nplan of {} poses:", b.budget);
    for s in &b.plan.setups {
        println!(
            "  {:<14} {:<6} {:>3} poses, {}: then {:.2} um",
            s.setup.id,
            s.setup.instrument.as_str(),
            s.poses,
            super::setup_words(&s.setup),
            s.expected_mm.unwrap_or(f64::NAN) * 1e3
        );
    }
    println!(
        "\n  after the plan          {:>6.2} um   ({} of {} determined)",
        f.after_mm * 1e3,
        b.plan.after().determined,
        b.plan.after().of
    );
    println!(
        "  {:>3} random poses instead {:>5.2} um   (median of {RANDOM_DRAWS} draws)",
        b.budget,
        b.random_mm * 1e3
    );
    println!(
        "  the tracker's own noise {:>6.2} um   (the floor no plan goes below)",
        f.floor_mm * 1e3
    );
    println!("\n{}", buys_words(b));
}

/// What the plan buys, in words.
fn buys_words(b: &Budgeted) -> String {
    let f = b.forecast;
    let (now, after, random) = (f.now_mm * 1e3, f.after_mm * 1e3, b.random_mm * 1e3);
    if now - after < WORTH * now {
        return format!(
            "the plan buys nothing: the campaign already predicts the TCP at {now:.2} um \
             (the tracker's own noise {:.2} um of it), and {} poses of these instruments \
             would not lower it by {:.0} %",
            f.floor_mm * 1e3,
            b.budget,
            WORTH * 100.0
        );
    }
    let versus = if after <= random {
        format!(
            "{:.0} % of what random poses buy",
            100.0 * (now - after) / (now - random).max(1e-9)
        )
    } else {
        "random poses would buy more: the plan's figures rest on the model".to_owned()
    };
    format!(
        "the plan buys {:.2} um of held-out RMS ({now:.2} -> {after:.2} um; {versus}); what \
         is left above the noise floor: {:.2} um",
        now - after,
        (after * after - (f.floor_mm * 1e3).powi(2)).max(0.0).sqrt()
    )
}

fn print_budgets(all: &[Budgeted]) {
    println!("\nby budget (expected held-out RMS):");
    println!(
        "  {:>6} {:>16} {:>16}",
        "poses", "after the plan", "random poses"
    );
    for b in all {
        println!(
            "  {:>6} {:>13.2} um {:>13.2} um",
            b.budget,
            b.forecast.after_mm * 1e3,
            b.random_mm * 1e3
        );
    }
}

/// Where these instruments buy nothing: the other instruments' plans of the same budget,
/// those that would buy something named best first.
fn print_nothing_to_gain(
    start: &Start,
    unknowns: &Unknowns,
    (instruments, budget): (&[Instrument], usize),
    evaluation: &Evaluation,
) -> anyhow::Result<()> {
    let names: Vec<&str> = instruments.iter().map(|i| super::spelling(*i)).collect();
    let mut better: Vec<(f64, Instrument)> = Vec::new();
    let mut now = f64::NAN;
    for other in ALL.into_iter().filter(|i| !instruments.contains(i)) {
        let setups: Vec<CandidateSetup> = plan::candidates(&[other])?;
        let planner = AccuracyPlanner::new(start, unknowns, &setups, evaluation)?;
        let (_, f) = planner.plan(budget)?;
        now = f.now_mm;
        if f.now_mm - f.after_mm >= WORTH * f.now_mm {
            better.push((f.after_mm, other));
        }
    }
    better.sort_by(|a, b| a.0.total_cmp(&b.0));
    if better.is_empty() {
        println!(
            "nothing to gain with {}, nor with any other instrument in {budget} poses: try \
             another model (rpkm diagnose: an effect the model lacks) or more poses (--budget)",
            names.join(", ")
        );
        return Ok(());
    }
    let tries: Vec<String> = better
        .iter()
        .map(|(mm, i)| format!("--instruments {} ({:.2} um)", super::spelling(*i), mm * 1e3))
        .collect();
    println!(
        "nothing to gain with {}; try {} (from {:.2} um, {budget} poses)",
        names.join(", "),
        tries.join(", or "),
        now * 1e3
    );
    Ok(())
}

fn comments(b: &Budgeted, where_words: &str) -> Vec<String> {
    let f = b.forecast;
    let mut out = vec![
        "rpkm plan: x, y are target TCP positions (mm), nothing measured yet".to_owned(),
        format!(
            "expected held-out RMS ({where_words}, each setup's zero removed): now {:.2} um, \
             after the plan {:.2} um, {} random poses {:.2} um, noise floor {:.2} um",
            f.now_mm * 1e3,
            f.after_mm * 1e3,
            b.budget,
            b.random_mm * 1e3,
            f.floor_mm * 1e3
        ),
    ];
    for s in &b.plan.setups {
        let back = if s.setup.return_pose().is_some() {
            ", its last pose the return to its reset (drift check)"
        } else {
            ""
        };
        out.push(format!(
            "setup {} ({}, {} poses{back}): then {:.2} um",
            s.setup.id,
            s.setup.instrument.as_str(),
            s.poses,
            s.expected_mm.unwrap_or(f64::NAN) * 1e3
        ));
    }
    out
}
