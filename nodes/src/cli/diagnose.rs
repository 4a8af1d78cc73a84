//! `rpkm diagnose`: where the model fails, which physical effect is missing, and the held-out
//! error once it is added. Physics in `rpkm_core::diagnose`; here the terminal summary, the
//! JSON and the HTML report.

use super::{bad_input, read_campaign, write_json};
use crate::plot;
use anyhow::Context;
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::{self, Diagnosis, Options};
use rpkm_core::effects::{self, Effect};
use rpkm_core::params::Model;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Find the physical effect the model is missing.
///
/// 1. Calibrates the current model (geometry, plus the effects given with --effects) and tests
///    its residual against the instruments' noise (chi-square).
/// 2. Tries every effect of the library not yet in the model: parallelogram, preload_elastic,
///    thermal, encoder_scale, guide_straightness, instrument_alignment; for each, its
///    parameters, a nested F-test, the fraction of the residual above the noise it explains
///    and the held-out RMS after adding it. Ranked best first (BIC).
/// 3. Names the missing effect, or says that nothing is missing.
/// 4. When a structured residual remains that no effect explains, points at the covariate,
///    drive force, time or workspace term it follows.
///
/// Then add the named effect and diagnose again: the next one, or "nothing is missing".
///
/// Example:
///   rpkm diagnose campaign.csv --model 24 --validate held_out.csv --report diag/
///   rpkm diagnose campaign.csv --effects thermal --validate held_out.csv --json d.json
#[derive(clap::Args, Debug)]
pub struct DiagnoseArgs {
    /// Campaign CSV (spec format); covariates such as temp_machine are used by the effects.
    pub campaign: PathBuf,
    /// Geometric model: 24 (rod 5 tied to rod 4: a perfect parallel-holder) or 29.
    #[arg(long, default_value_t = 24)]
    pub model: u32,
    /// Effects already in the model, comma-separated (e.g. thermal,preload_elastic).
    #[arg(long, default_value = "")]
    pub effects: String,
    /// Held-out campaign: the RMS before and after each candidate, and the noise floor.
    #[arg(long)]
    pub validate: Option<PathBuf>,
    /// Write the diagnosis as JSON (`missing_effect`, `baseline`, `candidates`, ...).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write an HTML report with the plots into this folder.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Significance level of the tests.
    #[arg(long, default_value_t = 0.001)]
    pub alpha: f64,
    /// The instruments' stated noise, NAME=VALUE comma-separated or a YAML file (mm, rad for
    /// psi): lt (isotropic tracker), lt_along, lt_across, lt_across_per_m, kgm, dbb, li, psi,
    /// encoder, force (N, drive forces), tracker_x, tracker_y. Only the start of the estimation and the rating the
    /// estimates are compared with: the verdict does not hinge on it.
    #[arg(long)]
    pub noise: Option<String>,
    /// Manufacturing tolerances of the lengths (mm) and angles (mrad), one σ: the prior of
    /// the calibration.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance_mm: f64,
    #[arg(long, default_value_t = 1.0)]
    pub tolerance_mrad: f64,
    /// Threads the candidate effects are fitted on (0: every core). The diagnosis is the
    /// same, to the bit, whatever the number.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Fit every candidate effect to convergence instead of screening it first (by default
    /// each takes one Gauss-Newton step from the current model's fit, and only one that may
    /// be significant, p < 0.05, is fitted to convergence). The same verdict, slower; the
    /// candidates' figures then come from converged fits. Example:
    /// rpkm diagnose cal.csv --validate val.csv --no-screen
    #[arg(long)]
    pub no_screen: bool,
}

/// Effects of a comma-separated list, or a bad-input error naming the option.
pub fn parse_effects(list: &str) -> anyhow::Result<Vec<Box<dyn Effect>>> {
    effects::parse_list(list).map_err(|e| bad_input(format!("--effects: {e}")))
}

pub fn run(args: &DiagnoseArgs) -> anyhow::Result<()> {
    let model = Model::from_number(args.model)
        .ok_or_else(|| bad_input(format!("--model {}: expected 24 or 29", args.model)))?;
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        return Err(bad_input(format!(
            "--alpha {}: expected 0 < alpha < 1",
            args.alpha
        )));
    }
    let campaign = read_campaign(&args.campaign)?;
    let validation = args.validate.as_deref().map(read_campaign).transpose()?;
    let in_model = parse_effects(&args.effects)?;
    let refs: Vec<&dyn Effect> = in_model.iter().map(|e| e.as_ref()).collect();
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !(positive(args.tolerance_mm) && positive(args.tolerance_mrad)) {
        return Err(bad_input(
            "--tolerance-mm/--tolerance-mrad: expected positive numbers".to_owned(),
        ));
    }
    let opts = Options {
        model,
        alpha: args.alpha,
        noise: super::parse_noise(args.noise.as_deref())?,
        prior: rpkm_core::calib::Prior {
            length_mm: args.tolerance_mm,
            angle_rad: args.tolerance_mrad * 1e-3,
        },
        threads: args.threads,
        screen: !args.no_screen,
        ..Default::default()
    };
    let d = diagnose::diagnose(&campaign, validation.as_ref(), &refs, &opts)
        .with_context(|| format!("diagnosing {}", args.campaign.display()))?;
    print_summary(&campaign, &d);
    if let Some(path) = &args.json {
        write_json(path, &serde_json::to_value(&d)?)?;
        println!("\nwrote {}", path.display());
    }
    if let Some(dir) = &args.report {
        let page = write_report(dir, &campaign, &d, None)?;
        println!("report: {}", page.display());
    }
    Ok(())
}

/// A µm value to one decimal, `-` when absent (no held-out data).
pub fn um(v: Option<f64>) -> String {
    v.map_or("-".to_owned(), |v| format!("{v:.1}"))
}

/// The terminal summary.
pub fn print_summary(campaign: &Campaign, d: &Diagnosis) {
    let b = &d.baseline;
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
    println!(
        "\n1. The current model against the measurements\n   calibration RMS {:.1} um, held-out RMS {} um, noise floor {:.1} um",
        b.cal_rms_um,
        um(b.val_rms_um),
        b.noise_floor_um
    );
    println!(
        "   against the stated noise: chi2/dof {:.2} over {:.0} dof, p = {:.2e} (the verdict does not rest on it)",
        b.chi2_per_dof, b.dof, b.p_value,
    );
    if let Some((n, of)) = d.determined {
        println!(
            "   the campaign determined {n} of {of} parameter combinations better than their \
             tolerance; the rest stayed at the prior"
        );
    }
    if !d.noise_groups.is_empty() {
        println!("\n   noise per group, estimated from the residuals:");
        super::calibrate::print_noise_groups(&d.noise_groups, "   ");
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
    println!("   (um; urad for psi)\n   worst residuals:");
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
    println!("\n2. Effects tried (best first)");
    println!(
        "   {:<22} {:>6} {:>9} {:>11} {:>10} {:>10}",
        "effect", "signif", "explained", "chi2/dof", "val before", "val after"
    );
    for c in &d.candidates {
        println!(
            "   {:<22} {:>6} {:>8.0}% {:>11.2} {:>10} {:>10}",
            c.effect,
            if c.significant { "yes" } else { "no" },
            100.0 * c.explained_fraction,
            c.chi2_per_dof_after,
            um(c.val_rms_before_um),
            um(c.val_rms_after_um)
        );
    }
    for s in &d.skipped {
        println!("   {:<22} not tried: {}", s.effect, s.reason);
    }
    if let Some(c) = d.candidates.first() {
        println!("   evidence for {}: {}", c.effect, c.evidence);
    }
    let kind = serde_json::to_value(d.verdict_kind)
        .ok()
        .and_then(|v| v.as_str().map(str::to_owned))
        .unwrap_or_default();
    println!("\n3. Verdict ({kind}): {}", d.verdict);
    if let Some(u) = &d.unexplained {
        println!("\n4. Unexplained structure: {}", u.sentence);
        for (f, i, dir, r) in &u.also {
            println!("   also: {i} {dir} follows {f} (r = {r:.2})");
        }
    }
    println!("\n({})", d.test);
}

/// Residual heat maps of the worst directions, residual against time, the candidates'
/// explained fractions and held-out RMS; `after` adds the diagnosis with the named effect
/// added (the before/after comparison). Returns the page's path.
pub fn write_report(
    dir: &Path,
    campaign: &Campaign,
    d: &Diagnosis,
    after: Option<&Diagnosis>,
) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut html = String::from(
        "<!doctype html><meta charset=\"utf-8\"><title>rpkm diagnosis</title>\
         <body style=\"font-family:sans-serif;max-width:1100px\">",
    );
    let b = &d.baseline;
    let _ = write!(
        html,
        "<h1>rpkm diagnosis of {}</h1><p><b>{}</b></p>\
         <h2>1. Where the model fails</h2><p>{}: calibration RMS {:.1} µm, held-out RMS {} µm, \
         noise floor {:.1} µm; χ²/dof {:.2} (p = {:.1e}).</p>",
        plot::escape(&campaign.source),
        plot::escape(&d.verdict),
        plot::escape(&d.model),
        b.cal_rms_um,
        um(b.val_rms_um),
        b.noise_floor_um,
        b.chi2_per_dof,
        b.p_value
    );
    let mut groups: Vec<_> = d.groups.iter().filter(|g| g.rows >= 8).collect();
    groups.sort_by(|a, b| b.chi2_per_row.total_cmp(&a.chi2_per_row));
    let mut files: Vec<(String, String)> = Vec::new();
    for (k, g) in groups.iter().take(4).enumerate() {
        let pts: Vec<(f64, f64, f64)> = d
            .points
            .iter()
            .filter(|p| p.instrument == g.instrument && p.direction == g.direction)
            .map(|p| (p.x, p.y, p.value))
            .collect();
        let unit = if g.direction.starts_with("psi") {
            "µrad"
        } else {
            "µm"
        };
        let title = format!(
            "{} {} residual over the workspace (χ²/row {:.1})",
            g.instrument, g.direction, g.chi2_per_row
        );
        files.push((
            format!("residual_map_{k}.svg"),
            plot::heat_map(&title, &pts, unit),
        ));
        let series: Vec<(f64, f64)> = d
            .points
            .iter()
            .filter(|p| p.instrument == g.instrument && p.direction == g.direction)
            .map(|p| (p.t, p.value / p.sigma))
            .collect();
        if k == 0 {
            files.push((
                "residual_vs_time.svg".to_owned(),
                plot::line_chart(
                    &format!("{} {} residual against time", g.instrument, g.direction),
                    "t (s)",
                    "residual / σ",
                    &[("residual".to_owned(), series)],
                    &plot::LineOptions::SCATTER,
                ),
            ));
        }
    }
    if !d.candidates.is_empty() {
        let names: Vec<String> = d.candidates.iter().map(|c| c.effect.clone()).collect();
        files.push((
            "candidates.svg".to_owned(),
            plot::bar_chart(
                "Residual above noise explained by each effect",
                "explained (%)",
                &names,
                &[(
                    "explained".to_owned(),
                    d.candidates
                        .iter()
                        .map(|c| 100.0 * c.explained_fraction)
                        .collect(),
                )],
                &plot::BarOptions::default(),
            ),
        ));
        if b.val_rms_um.is_some() {
            let mut cats = vec!["current model".to_owned()];
            let mut vals = vec![b.val_rms_um.unwrap_or(f64::NAN)];
            for c in &d.candidates {
                cats.push(format!("+ {}", c.effect));
                vals.push(c.val_rms_after_um.unwrap_or(f64::NAN));
            }
            cats.push("noise floor".to_owned());
            vals.push(b.noise_floor_um);
            files.push((
                "held_out_rms.svg".to_owned(),
                plot::bar_chart(
                    "Held-out TCP RMS with each effect added",
                    "RMS (µm)",
                    &cats,
                    &[("held-out RMS".to_owned(), vals)],
                    &plot::BarOptions::default(),
                ),
            ));
        }
    }
    for (name, svg) in &files {
        std::fs::write(dir.join(name), svg).with_context(|| format!("writing {name}"))?;
        if name == "candidates.svg" {
            html.push_str("<h2>2. Which effect is missing</h2><table border=1 cellpadding=4><tr><th>effect</th><th>significant</th><th>explained</th><th>held-out after (µm)</th><th>evidence</th></tr>");
            for c in &d.candidates {
                let _ = write!(
                    html,
                    "<tr><td>{}</td><td>{}</td><td>{:.0} %</td><td>{}</td><td>{}</td></tr>",
                    c.effect,
                    c.significant,
                    100.0 * c.explained_fraction,
                    um(c.val_rms_after_um),
                    plot::escape(&c.evidence)
                );
            }
            html.push_str("</table>");
        }
        let _ = write!(html, "<p><img src=\"{name}\"></p>");
    }
    if let Some(u) = &d.unexplained {
        let _ = write!(
            html,
            "<h2>Unexplained structure</h2><p>{}</p>",
            plot::escape(&u.sentence)
        );
    }
    if let Some(a) = after {
        let _ = write!(
            html,
            "<h2>3. After adding {}</h2><p>{}</p><p>χ²/dof {:.2}, held-out RMS {} µm (floor {:.1} µm).</p>",
            plot::escape(&a.effects_in_model.join(", ")),
            plot::escape(&a.verdict),
            a.baseline.chi2_per_dof,
            um(a.baseline.val_rms_um),
            a.baseline.noise_floor_um
        );
    }
    let _ = write!(
        html,
        "<p><small>{}</small></p></body>",
        plot::escape(&d.test)
    );
    let page = dir.join("report.html");
    std::fs::write(&page, html).with_context(|| format!("writing {}", page.display()))?;
    Ok(page)
}
