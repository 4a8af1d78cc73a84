//! What `rpkm diagnose`, `rpkm calibrate` and the demo print and write of a diagnosis: the
//! summary on the terminal, the noise per group, the HTML report.

use crate::report::{ModelTable, Report};
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::ModelDiagnosis;
use rpkm_core::units::um_from_mm;
use rpkm_core::variance;
use rpkm_nodes::effects_file::EffectsFile;
use rpkm_nodes::words;
use std::path::{Path, PathBuf};

/// A µm value to one decimal, `-` when absent (no held-out data).
pub fn um(v: Option<f64>) -> String {
    v.map_or("-".to_owned(), |v| format!("{v:.1}"))
}

/// The terminal summary; `validation` the held-out campaign, whose covariates and poses are
/// compared with the calibration's beside the judge.
pub fn print_summary(campaign: &Campaign, validation: Option<&Campaign>, d: &ModelDiagnosis) {
    let with = if d.effects_in_model.is_empty() {
        String::new()
    } else {
        format!(" + {}", d.effects_in_model.join(" + "))
    };
    println!(
        "Diagnosis of {} ({} poses) with {}{with}",
        campaign.source,
        campaign.poses.len(),
        d.model
    );
    if let Some(why) = words::model_choice(d) {
        println!("   ({why})");
    }
    print_baseline(&d.baseline);
    if let Some(h) = &d.held_out {
        println!("   {}", words::held_out_judge(h));
    }
    if let Some(val) = validation {
        print_coverage(campaign, val, "   ");
    }
    if d.model_effects != d.effects_in_model {
        println!(
            "   fitted as {} (a family keeps the parts the data can tell apart, an effect the \
             refinement they need: a rod of its own stiffness)",
            d.model_effects.join(" + ")
        );
    }
    for u in &d.undecided {
        println!("   {}", words::undecided(u));
    }
    for a in rpkm_core::calib::anchored_terms(&d.effect_values) {
        println!("   ({})", words::anchored(&a));
    }
    for e in d.effect_values.iter().filter(|e| e.physical()) {
        match &e.held {
            None => println!(
                "   {}.{} = {}",
                e.effect,
                e.name,
                words::with_sigma(e.value, e.sigma, &e.unit)
            ),
            Some(why) => println!("   {}.{}: not fitted: {why}", e.effect, e.name),
        }
    }
    if let Some((n, of)) = d.determined {
        println!(
            "   the campaign determined {n} of {of} parameter combinations better than their \
             tolerance; the rest stayed at the prior"
        );
    }
    print_groups(d);
    print_effects(d);
    let kind = serde_json::to_value(d.verdict_kind)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default();
    println!("\n3. Verdict ({kind}): {}", words::verdict(d));
    if let Some(u) = &d.unexplained {
        println!("\n4. Unexplained structure: {}", words::follows(u));
        for t in &u.also {
            println!(
                "   also: {} {} follows {} (r = {:.2})",
                t.instrument, t.direction, t.feature, t.r
            );
        }
    }
    println!("\n({})", words::test(&d.test));
}

/// Section 1's figures: the current model's fit, its held-out RMS and the noise floors (µm),
/// its χ² against the stated noise.
fn print_baseline(b: &rpkm_core::diagnose::Baseline) {
    println!(
        "\n1. The current model against the measurements\n   calibration RMS {:.1} µm, held-out RMS {} µm, noise floor {:.1} µm",
        um_from_mm(b.cal_rms),
        um(b.val_rms.map(um_from_mm)),
        um_from_mm(b.noise_floor)
    );
    if let (Some(rms), Some(floor)) = (
        b.val_rms_relative.map(um_from_mm),
        b.noise_floor_relative.map(um_from_mm),
    ) {
        println!(
            "   with each setup's zero removed (the one reading all its poses share, which no \
             model predicts): held-out RMS {rms:.1} µm, noise floor {floor:.1} µm"
        );
    }
    println!(
        "   against the stated noise: chi2/dof {:.2} over {:.0} dof, p = {:.2e} (the verdict does not rest on it)",
        b.chi2_per_dof, b.dof, b.p_value,
    );
}

/// The noise per group, the residual per instrument and direction, the worst rows.
fn print_groups(d: &ModelDiagnosis) {
    if !d.noise_groups.is_empty() {
        println!("\n   noise per group, estimated from the residuals of the current model:");
        print_noise_groups(&d.noise_groups, "   ");
    }
    println!(
        "\n   {:<6} {:<14} {:>5} {:>10} {:>10} {:>9}",
        "instr", "direction", "rows", "RMS", "noise", "chi2/row"
    );
    for g in &d.groups {
        println!(
            "   {:<6} {:<14} {:>5} {:>10.2} {:>10.2} {:>9.1}",
            g.instrument, g.direction, g.rows, g.rms, g.noise, g.chi2_per_row
        );
    }
    println!("   (µm; µrad for psi)\n   worst residuals:");
    for p in d.points.iter().take(3) {
        println!(
            "     line {:>5} {:<5} {:<10} {:>9.2} ({:.1} sigma) at x {:.0}, y {:.0} mm",
            p.line,
            p.instrument,
            p.direction,
            p.value,
            p.value / p.sigma,
            p.x,
            p.y
        );
    }
}

/// The held-out campaign against the calibration's (covariates, their rates, poses): where
/// it reaches outside, by how much, each line starting with `indent`.
pub fn print_coverage(campaign: &Campaign, validation: &Campaign, indent: &str) {
    let c = rpkm_core::diagnose::held_out::coverage::coverage(campaign, validation);
    if let Some(said) = words::coverage(&c) {
        println!("{indent}{said}");
    }
    if let Some(said) = words::instrument_coverage(&c) {
        println!("{indent}{said}");
    }
}

/// Every effect tried, best first, and those not tried.
fn print_effects(d: &ModelDiagnosis) {
    println!("\n2. Effects tried (best first)");
    println!(
        "   {:<22} {:>6} {:>9} {:>11} {:>14}",
        "effect", "signif", "explained", "chi2/dof", "held-out after"
    );
    for c in &d.candidates {
        println!(
            "   {:<22} {:>6} {:>8.0}% {:>11.2} {:>14}",
            c.effect,
            if c.significant { "yes" } else { "no" },
            100.0 * c.explained_fraction,
            c.chi2_per_dof_after,
            um(c.val_rms_after.map(um_from_mm))
        );
    }
    if let Some(before) = d
        .candidates
        .iter()
        .find_map(|c| c.val_rms_before.map(um_from_mm))
    {
        println!("   {}", held_out_before(d, before));
    }
    for s in &d.skipped {
        println!("   {:<22} not tried: {}", s.effect, s.reason);
    }
    if d.compared_under.is_empty() {
        println!(
            "   (chi2/dof of every row under one noise: the current model's, estimated from the \
             campaign)"
        );
    } else {
        println!(
            "   (chi2/dof of every row under one noise, compared with the rows weighted by the \
             noise of the model with {}: significant at the stated noise)",
            d.compared_under.join(" and ")
        );
    }
    if !d.trials.is_empty() {
        println!("   models of several effects or parts:");
        for t in &d.trials {
            println!("     {}", words::trial(t));
        }
    }
    if let Some(c) = d.candidates.first() {
        println!("   evidence for {}: {}", c.effect, words::evidence(c));
    }
}

/// What the table's "held-out after" is compared with: the current model's held-out RMS as
/// measured, fitted as the candidates are (under their one noise), which differs from
/// section 1's (the current model under its own noise estimate).
fn held_out_before(d: &ModelDiagnosis, before_um: f64) -> String {
    let weighted = if d.compared_under.is_empty() {
        "the current model's own noise".to_owned()
    } else {
        format!(
            "the noise of the model with {}",
            d.compared_under.join(" and ")
        )
    };
    format!(
        "(held-out after: the held-out RMS as measured, µm, with the effect added; before it, \
         the current model fitted as the candidates are, under {weighted}: {before_um:.1} µm{})",
        d.baseline
            .val_rms
            .map(um_from_mm)
            .map_or(String::new(), |own| format!(
                "; section 1's {own:.1} µm is the current model under its own noise estimate"
            ))
    )
}

/// The file's effects as written, under the summary: what the candidates of the file were.
pub fn print_written(file: &EffectsFile) {
    println!("\n   effects of {}:", file.file);
    for e in &file.effects {
        let s = e.spec();
        let exprs: Vec<String> = s
            .targets
            .iter()
            .map(|(t, x)| format!("{t} = {x}"))
            .collect();
        println!("     {:<20} {}", s.name, exprs.join("; "));
    }
}

/// The HTML report (and the numbers of its error-vector maps as JSON) of `before` and, when
/// an effect was added, `after`; `stages` the models' table (None: the two diagnoses', at
/// the stated noise);
/// `written` the effects of an effects file with their expressions
/// ([`effects_file::expressions`]). Returns the page's path.
pub fn write_report(
    dir: &Path,
    command: &str,
    (campaign, validation): (&Campaign, Option<&Campaign>),
    before: &ModelDiagnosis,
    after: Option<&ModelDiagnosis>,
    (stages, written): (Option<ModelTable>, Vec<(String, String)>),
) -> anyhow::Result<PathBuf> {
    let stages = stages.unwrap_or_else(|| ModelTable {
        rows: std::iter::once(before)
            .chain(after)
            .map(Report::stage_of)
            .collect(),
        chi2_under: "the stated noise (the instruments' ratings, --noise)".to_owned(),
    });
    Report {
        command,
        campaign,
        validation,
        before,
        after,
        stages: stages.rows,
        chi2_under: stages.chi2_under,
        written,
    }
    .write(dir)
}

/// The rows of the noise table, each line starting with `indent`: each group's stated level
/// with where it comes from (the spec, rpkm's own where the spec gives none, or `--noise`).
pub fn print_noise_groups(groups: &[variance::GroupNoise], indent: &str) {
    println!(
        "{indent}{:<14} {:>10} {:>10} {:>8}  {:<5} stated by",
        "group", "stated", "estimated", "dof", "unit"
    );
    for g in groups {
        println!(
            "{indent}{:<14} {:>10.3} {:>10} {:>8.1}  {:<5} {}{}",
            g.group,
            g.assumed,
            words::estimated_level(g),
            g.dof,
            words::unit_label(g.unit),
            words::rated_by(g),
            if g.capped {
                "  (the estimation's cap: a bound, not an estimate)"
            } else if g.estimated_from_data {
                ""
            } else {
                "  (too few degrees of freedom: stated level kept)"
            }
        );
    }
}
