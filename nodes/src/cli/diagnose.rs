//! `rpkm diagnose`: where the model fails, which physical effect is missing, and the held-out
//! error once it is added. Physics in `rpkm_core::diagnose`; here the terminal summary, the
//! JSON and the HTML report.

use super::{bad_input, read_campaign, write_json};
use crate::effects_file::{self, EffectsFile};
use crate::report::{Report, Stage};
use crate::words;
use anyhow::Context;
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::{self, Diagnosis, Options};
use rpkm_core::effects::{self, Effect};
use rpkm_core::params::Model;
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
    /// Effects already in the model, comma-separated (e.g. thermal,preload_elastic): the
    /// library's, or those of --effects-file.
    #[arg(long, default_value = "")]
    pub effects: String,
    /// Effects written as data (YAML: name, summary, params with unit and prior, expressions
    /// of dq1..dq4, dx, dy, dp.NAME; docs/effects.md): tried as candidates beside the
    /// library's, and named by --effects. Example:
    ///   rpkm diagnose c.csv --effects-file mine.yaml --validate v.csv
    #[arg(long)]
    pub effects_file: Option<PathBuf>,
    /// Held-out campaign: the RMS before and after each candidate, and the noise floor.
    #[arg(long)]
    pub validate: Option<PathBuf>,
    /// Write the diagnosis as JSON (`missing_effect`, `baseline`, `candidates`, ...).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the report into this folder: report.html (one self-contained page: verdict,
    /// residual maps before and after adding the named effect, error vectors, noise) and
    /// report.json (the numbers behind the error-vector maps).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Significance level of the tests.
    #[arg(long, default_value_t = 0.001)]
    pub alpha: f64,
    /// The instruments' stated noise, NAME=VALUE comma-separated or a YAML file (mm, rad for
    /// psi): lt (isotropic tracker), lt_along, lt_across, lt_across_per_m, kgm, dbb, li, psi,
    /// encoder, force (N, drive forces), drive_position (the encoders in the force rows),
    /// tracker_x, tracker_y. Only the start of the estimation and the rating the
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

/// Effects of a comma-separated list (the library's, or the file's), or a bad-input error
/// naming the option.
pub fn parse_effects(
    list: &str,
    file: Option<&EffectsFile>,
) -> anyhow::Result<Vec<Box<dyn Effect>>> {
    effects_file::parse_list(list, file).map_err(|e| bad_input(format!("--effects: {e}")))
}

/// The effects file of --effects-file, read and checked against the campaigns it will meet
/// (bad input, exit 2, naming its file, line and column).
pub fn read_effects_file(
    path: Option<&Path>,
    campaigns: &[Option<&Campaign>],
) -> anyhow::Result<Option<EffectsFile>> {
    let Some(path) = path else {
        return Ok(None);
    };
    let mut columns: Vec<String> = Vec::new();
    for c in campaigns.iter().flatten() {
        columns.extend(c.covariate_names.iter().cloned());
    }
    let file = effects_file::read(path, &columns).map_err(|e| bad_input(e.to_string()))?;
    for c in campaigns.iter().flatten() {
        file.check(c).map_err(|e| bad_input(e.to_string()))?;
    }
    Ok(Some(file))
}

/// The file's effects not in the model: the candidates it offers.
pub fn offered<'a>(file: Option<&'a EffectsFile>, in_model: &[&dyn Effect]) -> Vec<&'a dyn Effect> {
    file.map(EffectsFile::all)
        .unwrap_or_default()
        .into_iter()
        .filter(|e| !in_model.iter().any(|m| m.name() == e.name()))
        .collect()
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
    let file = read_effects_file(
        args.effects_file.as_deref(),
        &[Some(&campaign), validation.as_ref()],
    )?;
    let in_model = parse_effects(&args.effects, file.as_ref())?;
    let refs: Vec<&dyn Effect> = in_model.iter().map(std::convert::AsRef::as_ref).collect();
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
    let offer = offered(file.as_ref(), &refs);
    let d = diagnose::diagnose_among(&campaign, validation.as_ref(), &refs, &offer, &opts)
        .with_context(|| format!("diagnosing {}", args.campaign.display()))?;
    print_summary(&campaign, &d);
    if let Some(f) = &file {
        print_written(f);
    }
    if let Some(path) = &args.json {
        let mut json = crate::words::diagnosis_json(&d)?;
        if let Some(f) = &file {
            json["effects_file"] = effects_file::to_json(f);
        }
        write_json(path, &json)?;
        println!("\nwrote {}", path.display());
    }
    if let Some(dir) = &args.report {
        let after = with_named_effect(&campaign, validation.as_ref(), (&refs, &offer), &opts, &d)?;
        let page = write_report(
            dir,
            "rpkm diagnose",
            &campaign,
            &d,
            after.as_ref(),
            (Vec::new(), effects_file::expressions(file.as_ref())),
        )?;
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

/// The noise per group, the residual per instrument and direction, the worst rows.
fn print_groups(d: &Diagnosis) {
    if !d.noise_groups.is_empty() {
        let with = if d.noise_estimated_with.is_empty() {
            String::new()
        } else {
            format!(" (the model with {})", d.noise_estimated_with.join(" and "))
        };
        println!("\n   noise per group, estimated from the residuals{with}:");
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
}

/// Every effect tried, best first, and those not tried.
fn print_effects(d: &Diagnosis) {
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
        println!("   evidence for {}: {}", c.effect, words::evidence(c));
    }
}

/// The file's effects as written, under the summary: what the candidates of the file were.
fn print_written(file: &EffectsFile) {
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

/// The diagnosis with the effect `d` names added to the model (diagnosed again), if it names
/// one: the "after" of the report. `offered` are the written effects tried besides the
/// library (the named one may be one of them).
pub fn with_named_effect(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    (in_model, offered): (&[&dyn Effect], &[&dyn Effect]),
    opts: &Options,
    d: &Diagnosis,
) -> anyhow::Result<Option<Diagnosis>> {
    let Some(missing) = &d.missing_effect else {
        return Ok(None);
    };
    let from_library;
    let effect: &dyn Effect = if let Some(e) = offered.iter().copied().find(|e| e.name() == missing)
    {
        e
    } else {
        from_library = effects::by_name(missing)?;
        from_library.as_ref()
    };
    let mut with: Vec<&dyn Effect> = in_model.to_vec();
    with.push(effect);
    let rest: Vec<&dyn Effect> = offered
        .iter()
        .copied()
        .filter(|e| e.name() != missing)
        .collect();
    let after = diagnose::diagnose_among(campaign, validation, &with, &rest, opts)
        .with_context(|| format!("diagnosing with {missing} added"))?;
    Ok(Some(after))
}

/// The HTML report (and the numbers of its error-vector maps as JSON) of `before` and, when
/// an effect was added, `after`; `stages` the models' table (empty: the two diagnoses');
/// `written` the effects of an effects file with their expressions
/// ([`effects_file::expressions`]). Returns the page's path.
pub fn write_report(
    dir: &Path,
    command: &str,
    campaign: &Campaign,
    before: &Diagnosis,
    after: Option<&Diagnosis>,
    (stages, written): (Vec<Stage>, Vec<(String, String)>),
) -> anyhow::Result<PathBuf> {
    let stages = if stages.is_empty() {
        std::iter::once(before)
            .chain(after)
            .map(Report::stage_of)
            .collect()
    } else {
        stages
    };
    Report {
        command,
        campaign,
        before,
        after,
        stages,
        written,
    }
    .write(dir)
}
