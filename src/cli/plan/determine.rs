//! `rpkm plan --criterion determinant` (the parameter combinations a plan determines,
//! D-optimal) and `--separate` (the poses that tell two tied explanations apart).

use super::args::PlanArgs;
use super::output::{write_outputs, Drives};
use rpkm_core::analysis::nominal_campaign;
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::plan::separate::{self, Hypothesis, Pair, SeparationPlan};
use rpkm_core::plan::{self, DeterminationPlan, Start, Unknowns};
use rpkm_core::units::um_from_mm;
use serde_json::json;

/// `--criterion determinant`: the plan that determines most of what the campaign left.
pub fn run_determination(
    args: &PlanArgs,
    (start, unknowns): (&Start, &Unknowns),
    (instruments, drives): (&[Instrument], &Drives),
    calibrated: Option<(usize, usize)>,
    budget: usize,
) -> anyhow::Result<()> {
    let p = plan::plan_determination(start, unknowns, instruments, budget)?;
    print_determination(&p, calibrated);
    let design = plan::measured_in(p.design(), &drives.mode);
    write_outputs(args, (&design, drives), &determination_comments(&p), || {
        determination_json(&p)
    })
}

/// `--separate`: how far the campaign tells the pair apart, the sequence of poses of the
/// first instrument's setup that tells them apart most, and how far the campaign with it
/// does.
pub fn run_separation(
    args: &PlanArgs,
    (start, unknowns): (&Start, &Unknowns),
    (instrument, drives): (Instrument, &Drives),
    pair: &Pair,
    budget: usize,
) -> anyhow::Result<()> {
    let at = (start.model, start.noise);
    let before = separate::separation_of(start.campaign, start.params, at, unknowns, pair)?;
    let setup = plan::candidates(&[instrument])?.remove(0);
    let p = separate::separate(&setup, start.params, at, unknowns, pair, budget)?;
    let poses = plan::measured_in(p.poses.clone(), &drives.mode);
    let with = with_plan(start, &poses)?;
    let after = separate::separation_of(&with, start.params, at, unknowns, pair)?;
    print_separation(pair, (before, after), &p);
    let comments = vec![format!(
        "rpkm plan: separates {} from {}: the campaign now {:.2} sigma, with the plan {:.2} sigma (at {} and {})",
        pair.a,
        pair.b,
        before.sigma(),
        after.sigma(),
        size_words(pair.a, pair.size[0]),
        size_words(pair.b, pair.size[1]),
    )];
    write_outputs(args, (&poses, drives), &comments, || {
        separation_json(pair, (before, after), &p)
    })
}

/// The campaign of `start` with `poses` measured after it, on a machine at its parameters.
fn with_plan(start: &Start, poses: &[rpkm_core::design::PlannedPose]) -> anyhow::Result<Campaign> {
    let mut c = start.campaign.clone();
    let t0 = c.poses.last().map_or(0.0, |p| p.t);
    let planned = nominal_campaign(poses, start.params, start.model)?;
    for (k, mut p) in planned.poses.into_iter().enumerate() {
        p.t = t0 + 1.0 + k as f64;
        p.covariates = vec![None; c.covariate_names.len()];
        c.poses.push(p);
    }
    Ok(c)
}

pub fn size_words(h: Hypothesis, size: f64) -> String {
    match h {
        Hypothesis::LostMotion(_) => format!("{h} = {:.1} µm", um_from_mm(size)),
        Hypothesis::Parameter(_) => format!("{h} at its tolerance {size}"),
    }
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
        println!(
            "  {}: then {} of {} determined (effective {:.1})",
            super::output::setup_line(s),
            s.after.determined,
            s.after.of,
            s.after.effective
        );
    }
    let a = p.after();
    let gained = a.determined.saturating_sub(b.determined);
    println!(
        "\nafter the plan: {} of {} determined (+{gained}, effective {:.1} -> {:.1})",
        a.determined, a.of, b.effective, a.effective
    );
    if gained == 0 {
        println!(
            "the plan determines no combination the campaign left beyond its tolerance; it \
             narrows those it did (effective +{:.1}): try other instruments (--instruments) \
             or --criterion tcp for what it buys the TCP",
            a.effective - b.effective
        );
    }
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

/// A plan's setups as JSON (with the expected held-out RMS after each where it has one).
pub fn setups_json(p: &DeterminationPlan) -> serde_json::Value {
    json!(p.setups.iter().map(|s| json!({
        "setup": s.setup.id,
        "instrument": s.setup.instrument.as_str(),
        "reset": s.setup.reset.map(|(x, y)| [x, y]),
        "return": s.setup.return_pose().map(|r| [r.x, r.y]),
        "poses": s.poses,
        "points": s.points.iter().map(|&k| s.setup.points[k]).map(|(x, y)| [x, y]).collect::<Vec<_>>(),
        "after": s.after,
        "expected_um": s.expected_mm.map(um_from_mm),
    })).collect::<Vec<_>>())
}

fn determination_json(p: &DeterminationPlan) -> serde_json::Value {
    json!({
        "kind": "determine",
        "before": p.before,
        "after": p.after(),
        "setups": setups_json(p),
    })
}

fn print_separation(
    pair: &Pair,
    (before, after): (separate::Separation, separate::Separation),
    p: &SeparationPlan,
) {
    println!(
        "{} against {}: the campaign tells them apart by {:.2} sigma ({} true: {:.2}, {} true: {:.2})",
        pair.a, pair.b, before.sigma(), pair.a, before.a_from_b, pair.b, before.b_from_a
    );
    println!(
        "judged at {} and {}",
        size_words(pair.a, pair.size[0]),
        size_words(pair.b, pair.size[1])
    );
    let Some(alone) = p.after() else { return };
    println!(
        "\nafter the plan (the campaign and the plan's {} poses): {:.2} sigma ({:.2}, {:.2}), from {:.2}",
        p.poses.len(),
        after.sigma(),
        after.a_from_b,
        after.b_from_a,
        before.sigma()
    );
    println!(
        "the plan's poses alone tell them apart by {:.2} sigma; by the number of poses:",
        alone.sigma()
    );
    for k in [4, 9, 19, 39]
        .into_iter()
        .filter(|&k| k < p.after_each.len())
    {
        println!(
            "  the first {:>3} poses alone: {:.2} sigma",
            k + 1,
            p.after_each[k].sigma()
        );
    }
}

fn separation_json(
    pair: &Pair,
    (before, after): (separate::Separation, separate::Separation),
    p: &SeparationPlan,
) -> serde_json::Value {
    json!({
        "kind": "separate",
        "a": pair.a.to_string(),
        "b": pair.b.to_string(),
        "size": pair.size,
        "before": before,
        "before_sigma": before.sigma(),
        "after": after,
        "after_sigma": after.sigma(),
        "plan_alone": p.after(),
        "plan_alone_sigma": p.after().map(|s| s.sigma()),
        "plan_alone_each_sigma": p.after_each.iter().map(separate::Separation::sigma).collect::<Vec<_>>(),
        "poses": p.poses.iter().map(|q| json!({"setup": q.setup, "x": q.x, "y": q.y})).collect::<Vec<_>>(),
    })
}
