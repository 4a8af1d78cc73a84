//! `rpkm calibrate`: identify the geometric parameters from a campaign file.

use super::effect_stages::Stages;
use super::summary::print_noise_groups;
use super::{bad_input, read_campaign, write_json};
use rpkm_core::calib::{
    self, Calibration, CommandCalibration, CommandError, CommandRequest, Options, Scaling,
    Selection,
};
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::HeldOutErrors;
use rpkm_core::effects::{Effect, EffectSet};
use rpkm_core::params::{self, Model, Params, NAMES, N_PARAMS};
use rpkm_core::units::um_from_mm;
use rpkm_core::variance::NoiseEstimate;
use rpkm_nodes::calibration_file::{
    CalibrationFile, EffectValue, IdentifiedEntry, PosteriorCovariance,
};
use rpkm_nodes::effects_file::EffectsFile;
use serde_json::json;
use std::path::PathBuf;

/// Identify the parameters of the Scissors-Kinematics from a measurement campaign.
///
/// Every method of the thesis: laser tracker and grid encoder (inverse calibration with the
/// setups' reset poses), double ball-bar and laser interferometer (forward calibration, then
/// the q2 branch from virtual measurements), platform angle, self-calibration with q2, q3 as
/// followers. A campaign mixing instruments calibrates them together, each row weighted by its
/// instrument's noise.
///
/// Example:
///   rpkm calibrate campaign.csv --model 29 --params auto --validate held_out.csv --json cal.json
#[derive(clap::Args, Debug)]
#[command(after_help = super::library_help::library())]
pub struct CalibrateArgs {
    /// Campaign CSV (spec format: t, setup, instrument, reset, q1..q4, f1..f4, follower, x, y, r, psi, covariates).
    pub campaign: PathBuf,
    /// Geometric model: 24 (perfect parallel-holder, ψ ≡ γ2) or 29 (complete).
    #[arg(long, default_value_t = 29)]
    pub model: u32,
    /// Parameters to identify: `map` (every parameter of the model, each held near its
    /// nominal value by its manufacturing tolerance, --tolerance-mm/--tolerance-mrad: the
    /// campaign determines what it sees, the rest stays at the prior; the same calibration
    /// as `rpkm diagnose` and the calibrator node), `auto` (the thesis's observability
    /// selection: QR-pivot order while the condition number stays below --max-condition) or
    /// a comma-separated list (l1,gamma2,...).
    #[arg(long, default_value = "map")]
    pub params: String,
    /// The tolerances of --params map.
    #[command(flatten)]
    pub tolerance: super::prior_args::PriorArgs,
    /// The instruments' stated noise, NAME=VALUE comma-separated or a YAML file (mm, rad for
    /// psi): lt (isotropic tracker), lt_along, lt_across, lt_across_per_m, kgm, dbb, li, psi,
    /// encoder, force (N, drive forces), drive_position (the encoders in the force rows),
    /// tracker_x, tracker_y. Default: the spec's figures. Example:
    /// --noise lt=0.005,kgm=0.001,encoder=0.0005
    #[arg(long)]
    pub noise: Option<String>,
    /// Weight the rows by the stated noise as it is, instead of estimating each group's level
    /// from the campaign (variance components).
    #[arg(long)]
    pub no_noise_estimation: bool,
    /// Condition number limit of the automatic selection (Schröer: 100 for real calibrations).
    #[arg(long, default_value_t = 100.0)]
    pub max_condition: f64,
    /// Held-out campaign: reports the TCP RMS with nominal and identified parameters, and the gain.
    #[arg(long)]
    pub validate: Option<PathBuf>,
    /// Write the result as JSON (parameters by spec name, their σ and full covariance, RMS,
    /// condition number, gain ...): the calibrator node's `geometry_file` starts its online
    /// tracker from that covariance.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Starting parameters: JSON object of name → value (mm, rad); default the nominal set.
    #[arg(long)]
    pub start: Option<PathBuf>,
    /// Parameter scaling: `column` (column norms, eq. 3.25) or `range` (0.1 mm, 1°; Schröer).
    #[arg(long, default_value = "column")]
    pub scaling: String,
    /// Outlier elimination threshold in standard deviations per direction (0 = keep all, the
    /// default: the same rows as `rpkm diagnose`; 3 = the thesis's 3-sigma elimination).
    #[arg(long, default_value_t = 0.0)]
    pub outlier_sigma: f64,
    /// Tie rod 5 to rod 4 in the dependency matrix (perfect parallel-holder in model 29).
    #[arg(long)]
    pub perfect_parallelogram: bool,
    /// Physical effects to add to the model, in order (e.g. thermal,preload_elastic): the
    /// geometry is calibrated with them (the parameters, σ and covariance printed and in
    /// --json are the model's with the effects, whose own parameters follow), and the output
    /// shows the error falling effect by effect (table; chart with --chart).
    /// The library's effects are listed below (with thermal_lag beside thermal, the time
    /// constant τ = lag/α is printed with its σ). A family named whole fits
    /// every part (thermal: rods, frame and scales); `thermal:rods` pins one,
    /// `thermal:rods+frame` several (the name the diagnosis advises).
    #[arg(long, default_value = "")]
    pub effects: String,
    /// Effects written as data (YAML, docs/effects.md) that --effects may name; their
    /// parameters (value, σ, unit) go into --json with the expressions. Example:
    ///   rpkm calibrate c.csv --effects-file mine.yaml --effects lost_motion_q4 --json cal.json
    #[arg(long)]
    pub effects_file: Option<PathBuf>,
    /// With --effects: write the chart of the held-out RMS per added effect (SVG).
    #[arg(long)]
    pub chart: Option<PathBuf>,
    /// Write the diagnosis report into this folder (report.html, one self-contained page, and
    /// report.json): the model without effects against the model with --effects (or, without
    /// --effects, with the effect the diagnosis names): residual maps before and after, error
    /// vectors, the held-out RMS per stage, the noise. Example:
    ///   rpkm calibrate c.csv --model 24 --effects thermal --validate v.csv --report cal-report/
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Threads the rows are evaluated on (0: every core). The result is the same to the bit
    /// on any number: the rows are summed in fixed pieces of 256 poses, in order.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Record the calibration in the machine's history (an SQLite file, made if missing, or
    /// a PostgreSQL URL, its password as libpq finds it: PGPASSWORD, ~/.pgpass or
    /// PGPASSFILE, PGSERVICE) under --machine: `rpkm history DB --machine NAME` then says what
    /// changed since the last one and how each parameter trends. Example:
    ///   rpkm calibrate c.csv --validate v.csv --history cell.db --machine cell-1
    #[arg(long, requires = "machine")]
    pub history: Option<String>,
    /// The machine's name in the history (with --history).
    #[arg(long, requires = "history")]
    pub machine: Option<String>,
    /// When the campaign was measured, for the history: RFC 3339 (2026-03-01T10:00:00Z) or
    /// a date (2026-03-01, midnight UTC); default: now.
    #[arg(long, requires = "history")]
    pub at: Option<String>,
}

/// Parse a parameter list of spec names.
pub fn parse_param_list(list: &str, model: Model) -> anyhow::Result<Vec<usize>> {
    let mut out = Vec::new();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let i = params::index_of(name).ok_or_else(|| {
            bad_input(format!(
                "--params: unknown parameter `{name}` (expected one of {})",
                NAMES.join(", ")
            ))
        })?;
        if !model.has_param(i) {
            return Err(bad_input(format!(
                "--params: `{name}` is not a parameter of {model}"
            )));
        }
        out.push(i);
    }
    if out.is_empty() {
        return Err(bad_input("--params: empty list".into()));
    }
    Ok(out)
}

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let model = Model::from_number(args.model)
        .ok_or_else(|| bad_input(format!("--model {}: expected 24 or 29", args.model)))?;
    let campaign = read_campaign(&args.campaign)?;
    let validation = args.validate.as_deref().map(read_campaign).transpose()?;
    let start = match &args.start {
        Some(path) => super::read_params(path)?,
        None => Params::nominal(),
    };
    let opts = options(args, model)?;
    // The geometry comes out of the model with the effects (what --json hands to the nodes).
    let file = super::effect_stages::read_effects_file(
        args.effects_file.as_deref(),
        &[Some(&campaign), validation.as_ref()],
    )?;
    let effects = super::effect_stages::parse_effects(&args.effects, file.as_ref())?;
    let refs: Vec<&dyn Effect> = effects.iter().map(AsRef::as_ref).collect();
    let CommandCalibration {
        effects: set,
        calibration: cal,
        noise,
    } = calib::calibrate_command(&CommandRequest {
        noise: weighting(args),
        ..CommandRequest::new(&campaign, &start, &opts, &refs)
    })
    .map_err(|e| match e {
        CommandError::Effects(e) => bad_input(format!("--effects: {e}")),
        // A calibration error is the campaign's (exit 2, rpkm_nodes::error::exit_code).
        CommandError::Calibration(e) => {
            anyhow::Error::new(e).context(format!("calibrating {}", args.campaign.display()))
        }
    })?;
    let val = validation
        .as_ref()
        .map(|v| validate_with(v, &start, &cal, &noise, (&refs, &set)))
        .transpose()?;
    print_report(&campaign, &cal, val.as_ref());
    if let Some(v) = &validation {
        super::summary::print_coverage(&campaign, v, "");
    }
    print_noise(&noise);
    let returns = drift_checks(&campaign, (&cal, &set), &opts.noise, &noise)?;
    print_returns(&returns.0, &returns.1);
    let stages = if refs.is_empty() {
        None
    } else {
        Some(effect_stages(
            args,
            model,
            &refs,
            &campaign,
            validation.as_ref(),
        )?)
    };
    let mut verdict = None;
    if let Some(dir) = &args.report {
        let (page, said) = write_report(
            dir,
            (args, model, &refs, file.as_ref()),
            &campaign,
            validation.as_ref(),
            stages.as_ref(),
        )?;
        verdict = Some(said);
        println!("\nreport: {}", page.display());
    }
    if let Some(path) = &args.json {
        let file = file.as_ref().map(rpkm_nodes::effects_file::to_json);
        write_calibration_json(
            path,
            (&cal, &noise, file),
            (val.as_ref(), stages.as_ref(), &returns),
            (&campaign, validation.as_ref()),
        )?;
    }
    record_history(
        args,
        (&campaign, &cal, &noise, &opts.selection),
        val.as_ref(),
        verdict,
    )
}

/// Every return to a setup's reset pose, judged.
type Returns = Vec<rpkm_core::returns::ReturnDrift>;

/// The drift checks of every return to a setup's reset pose under the calibrated model:
/// judged against the `stated` noise (the estimate's group takes a drift in and hides it) and
/// against the `estimated` one (where the stated is far too pessimistic, it hides one).
fn drift_checks(
    campaign: &Campaign,
    (cal, set): (&Calibration, &EffectSet),
    stated: &rpkm_core::noise::NoiseModel,
    estimated: &NoiseEstimate,
) -> anyhow::Result<(Returns, Returns)> {
    let corr = set.corrections(&cal.theta, &cal.params);
    let check = |n| {
        rpkm_core::returns::drift_checks(campaign, (&cal.params, cal.model), &corr, n)
            .map_err(|e| bad_input(e.to_string()))
    };
    Ok((check(stated)?, check(&estimated.model)?))
}

/// `--json`: the calibration's file (what the nodes read) with the report's figures, the
/// returns under the stated and the estimated noise and the held-out campaign's.
fn write_calibration_json(
    path: &std::path::Path,
    (cal, noise, file): (&Calibration, &NoiseEstimate, Option<serde_json::Value>),
    (val, stages, returns): (Option<&Validation>, Option<&Stages>, &(Returns, Returns)),
    (campaign, held_out): (&Campaign, Option<&Campaign>),
) -> anyhow::Result<()> {
    let mut out = calibration_json(cal, (noise, file), val, stages)?;
    out.report
        .insert("returns".into(), serde_json::to_value(&returns.0)?);
    out.report.insert(
        "returns_under_estimated_noise".into(),
        serde_json::to_value(&returns.1)?,
    );
    if let Some(v) = held_out {
        let judge = val.and_then(|v| v.judge.as_ref());
        super::held_out_poses::held_out_json(&mut out.report, (campaign, v), judge)?;
    }
    write_json(path, &out.to_value()?)?;
    println!("\nwrote {}", path.display());
    Ok(())
}

/// `--history`: the calibration recorded in the machine's history, with the held-out RMS
/// and the verdict it had (None: not asked for).
fn record_history(
    args: &CalibrateArgs,
    (campaign, cal, noise, selection): (&Campaign, &Calibration, &NoiseEstimate, &Selection),
    val: Option<&Validation>,
    verdict: Option<String>,
) -> anyhow::Result<()> {
    let (Some(db), Some(machine)) = (&args.history, &args.machine) else {
        return Ok(());
    };
    let at_s = rpkm_nodes::history::time_of(args.at.as_deref())
        .map_err(|e| bad_input(format!("--at {e}")))?;
    let record = rpkm_nodes::history::record_of(&rpkm_nodes::history::Made {
        machine,
        at_s,
        source: "rpkm calibrate",
        campaign,
        calibration: cal,
        noise,
        selection,
        held_out_rms_um: val.map(|v| v.rms_after_um),
        verdict,
    })?;
    let mut store = rpkm_history::Store::open(db)?;
    for n in store.notes() {
        eprintln!("warning: {n}");
    }
    // the same measurements calibrated before: said, as they are no new measurement
    let same = store
        .calibrations(machine)?
        .into_iter()
        .find(|c| {
            c.record.campaign.digest == record.campaign.digest && c.record.at_s != record.at_s
        })
        .map(|c| c.id);
    if let Some(id) = same {
        println!(
            "\nthe same campaign as calibration {id} (SHA-256 {}...): recorded again, not an \
             independent measurement of {machine}",
            &record.campaign.digest[..record.campaign.digest.len().min(12)]
        );
    }
    match store.record_calibration(&record)? {
        Some(id) => println!(
            "\nrecorded as calibration {id} of {machine} in {}",
            store.location()
        ),
        None => println!(
            "\nalready recorded in {} (same machine, time and campaign)",
            store.location()
        ),
    }
    Ok(())
}

/// The calibration's options from the command line, each flag checked.
fn options(args: &CalibrateArgs, model: Model) -> anyhow::Result<Options> {
    let prior = args.tolerance.prior()?;
    let selection = match args.params.as_str() {
        "map" => Selection::Prior(prior),
        "auto" => Selection::Auto {
            max_condition: args.max_condition,
        },
        list => Selection::List(parse_param_list(list, model)?),
    };
    let scaling = match args.scaling.as_str() {
        "column" => Scaling::ColumnNorm,
        "range" => Scaling::Range,
        other => {
            return Err(bad_input(format!(
                "--scaling {other}: expected `column` or `range`"
            )))
        }
    };
    if args.threads > 1024 {
        return Err(bad_input(format!(
            "--threads {}: expected 0 (every core) to 1024",
            args.threads
        )));
    }
    let links = if args.perfect_parallelogram {
        calib::Link::perfect_parallelogram()
    } else {
        Vec::new()
    };
    Ok(Options {
        model,
        selection,
        links,
        scaling,
        outlier_sigma: (args.outlier_sigma > 0.0).then_some(args.outlier_sigma),
        noise: super::parse_noise(args.noise.as_deref())?,
        threads: args.threads,
        ..Default::default()
    })
}

/// The `--json` file: the calibration, its noise and the effect stages.
fn calibration_json(
    cal: &Calibration,
    (noise, file): (&NoiseEstimate, Option<serde_json::Value>),
    val: Option<&Validation>,
    stages: Option<&Stages>,
) -> anyhow::Result<CalibrationFile> {
    let mut out = report_json(cal, val)?;
    // the written effects as written: what their parameters in `effects` mean
    out.effects_file = file.map(serde_json::from_value).transpose()?;
    let report = &mut out.report;
    report.insert("noise".into(), serde_json::to_value(&noise.groups)?);
    report.insert("determined".into(), serde_json::to_value(cal.determined)?);
    if let Some(st) = stages {
        report.insert("effect_stages".into(), serde_json::to_value(&st.rows)?);
        report.insert(
            "effect_stages_chi2_under".into(),
            st.chi2_under.clone().into(),
        );
        // the stages' last model as the data settle it, where not as given
        if let Some(fitted) = &st.settled_as {
            report.insert(
                "effect_stages_settled_as".into(),
                serde_json::to_value(fitted)?,
            );
        }
    }
    Ok(out)
}

/// The drift checks: each setup's return to its reset pose against the stated noise, and
/// against the noise the campaign shows (`estimated`, the same returns in the same order).
fn print_returns(
    returns: &[rpkm_core::returns::ReturnDrift],
    estimated: &[rpkm_core::returns::ReturnDrift],
) {
    if returns.is_empty() {
        return;
    }
    println!(
        "\ndrift checks (each return to a setup's reset pose against the stated noise, --noise, \
         then against the noise estimated from the campaign):"
    );
    for (d, e) in returns.iter().zip(estimated) {
        println!("  {}", rpkm_nodes::words::return_drift(d));
        println!("    {}", rpkm_nodes::words::return_drift_estimated(e));
    }
}

/// How the rows are weighted: each noise group's level estimated from the campaign unless
/// `--no-noise-estimation`.
fn weighting(args: &CalibrateArgs) -> calib::Noise {
    if args.no_noise_estimation {
        calib::Noise::Stated
    } else {
        calib::Noise::ESTIMATE
    }
}

/// The noise table: stated against estimated, per group.
pub fn print_noise(noise: &NoiseEstimate) {
    if noise.groups.is_empty() {
        return;
    }
    println!(
        "\nnoise per group (estimated from the campaign's residuals, {} rounds):",
        noise.rounds
    );
    print_noise_groups(&noise.groups, "  ");
}

/// The diagnosis's calibration: tolerance prior, noise estimated, no outlier elimination.
fn diagnosis_options(
    args: &CalibrateArgs,
    model: Model,
) -> anyhow::Result<rpkm_core::diagnose::DiagnosisOptions> {
    Ok(rpkm_core::diagnose::DiagnosisOptions {
        model: if args.perfect_parallelogram {
            Model::M24
        } else {
            model
        },
        noise: super::parse_noise(args.noise.as_deref())?,
        weighting: weighting(args),
        ..Default::default()
    })
}

/// The report of --report: the model without effects diagnosed, against the model with
/// --effects (or with the effect the diagnosis names); the stages of --effects as its table.
/// The page, and the verdict on the model calibrated (with --effects: with them) in words.
fn write_report(
    dir: &std::path::Path,
    (args, model, refs, file): (&CalibrateArgs, Model, &[&dyn Effect], Option<&EffectsFile>),
    campaign: &Campaign,
    validation: Option<&Campaign>,
    stages: Option<&Stages>,
) -> anyhow::Result<(std::path::PathBuf, String)> {
    use rpkm_core::diagnose;
    let opts = diagnosis_options(args, model)?;
    let offer = super::effect_stages::offered(file, &[]);
    let offer = offer.as_slice();
    let before = diagnose::diagnose_among(campaign, validation, &[], offer, &opts)?;
    let after = if refs.is_empty() {
        super::effect_stages::with_named_effect(campaign, validation, (&[], offer), &opts, &before)?
    } else {
        Some(diagnose::diagnose(campaign, validation, refs, &opts)?)
    };
    let stages = stages.map(|st| crate::report::ModelTable {
        rows: st
            .rows
            .iter()
            .map(|s| crate::report::ModelRow {
                model: s.model.clone(),
                cal_rms_um: s.cal_rms_um,
                val_rms_um: s.val_rms_um,
                chi2_per_dof: s.chi2_per_dof,
            })
            .collect(),
        chi2_under: st.chi2_under.clone(),
    });
    let calibrated = if refs.is_empty() {
        &before
    } else {
        after.as_ref().unwrap_or(&before)
    };
    let verdict = rpkm_nodes::words::verdict(calibrated);
    let page = super::summary::write_report(
        dir,
        "rpkm calibrate",
        (campaign, validation),
        &before,
        after.as_ref(),
        (stages, rpkm_nodes::effects_file::expressions(file)),
    )?;
    Ok((page, verdict))
}

/// Calibrate with the effects of --effects added one by one, the diagnosis's way (its
/// options), print the table and write the chart.
fn effect_stages(
    args: &CalibrateArgs,
    model: Model,
    effects: &[&dyn Effect],
    campaign: &Campaign,
    validation: Option<&Campaign>,
) -> anyhow::Result<Stages> {
    let opts = diagnosis_options(args, model)?;
    let stages = Stages::of(campaign, validation, effects, &opts)?;
    stages.print();
    if let Some(path) = &args.chart {
        stages.write_chart(path)?;
    }
    Ok(stages)
}

/// Held-out TCP errors with the starting and the identified parameters, and the held-out
/// judge of the calibrated model (the diagnosis's own: zero removed, the model's floor).
pub struct Validation {
    pub rms_before_um: f64,
    pub rms_after_um: f64,
    pub gain: f64,
    pub values: usize,
    pub judge: Option<rpkm_core::diagnose::HeldOutCheck>,
}

/// The held-out TCP errors of the calibration `cal` of the model with the `effects` bound
/// to its campaign (the diagnosis's held-out judge, one evaluation for every command),
/// against the starting parameters without them.
fn validate_with(
    val: &Campaign,
    start: &Params,
    cal: &Calibration,
    noise: &NoiseEstimate,
    (effects, set): (&[&dyn Effect], &EffectSet),
) -> anyhow::Result<Validation> {
    let judge = rpkm_core::diagnose::judge_calibration(
        val,
        noise,
        (effects, set),
        cal,
        rpkm_core::diagnose::DiagnosisOptions::default().alpha,
    )
    .map_err(|e| bad_input(format!("{}: {e}", val.source)))?;
    let before =
        HeldOutErrors::of_geometry(val, start, cal.model).map_err(|e| bad_input(format!("{e}")))?;
    if before.values.is_empty() {
        return Err(bad_input(format!(
            "{}: no held-out TCP measurement (lt, kgm, dbb, li_x, li_y rows)",
            val.source
        )));
    }
    let after = &judge.figures.errors;
    Ok(Validation {
        rms_before_um: um_from_mm(before.rms),
        rms_after_um: um_from_mm(after.rms),
        gain: calib::gain(&before.values, &after.values),
        values: before.values.len(),
        judge: Some(judge),
    })
}

fn unit_scale(r: &calib::DirectionRms) -> (f64, &'static str) {
    if r.is_angle {
        (1e6, "µrad")
    } else if r.is_force {
        (1.0, "N")
    } else {
        (1e3, "µm")
    }
}

fn print_report(campaign: &Campaign, cal: &Calibration, val: Option<&Validation>) {
    println!(
        "Calibration of {} with {} ({} rows, {} LM iterations)",
        campaign.source, cal.model, cal.rows, cal.iterations
    );
    println!(
        "\n{:<8} {:>14} {:>14} {:>6}   {:<5} identified - nominal",
        "param", "nominal", "identified", "step", "unit"
    );
    for id in &cal.identified {
        let (s, u, base) = if params::unit(id.index) == params::Unit::Rad {
            (1e3, "mrad", "rad")
        } else {
            (1.0, "mm", "mm")
        };
        println!(
            "{:<8} {:>14.6} {:>14.6} {:>6}   {u:<5} {}",
            id.name,
            id.nominal * s,
            id.value * s,
            id.step,
            rpkm_nodes::words::with_sigma(id.value - id.nominal, id.sigma, base)
        );
    }
    print_effects(&cal.effects);
    for tau in calib::time_constants(cal) {
        println!(
            "{:<24} {}  (lag_{p} / alpha_{p}: positive where the thermometer lags the {p})",
            tau.name,
            rpkm_nodes::words::with_sigma(tau.value, tau.sigma, "s"),
            p = tau.part
        );
    }
    println!(
        "\n{:<8} {:<14} {:>6} {:>12} {:>12}",
        "instr.", "direction", "rows", "RMS before", "RMS after"
    );
    for r in &cal.rms {
        let (s, u) = unit_scale(r);
        println!(
            "{:<8} {:<14} {:>6} {:>9.2} {u} {:>9.3} {u}",
            r.instrument,
            r.direction,
            r.rows,
            r.rms_before * s,
            r.rms_after * s
        );
    }
    println!(
        "\ncondition number of the identification: {}",
        rpkm_nodes::words::condition(cal.condition_number, cal.determined)
    );
    println!(
        "chi-square per degree of freedom: {:.2} (1 = residual at the instruments' noise)",
        cal.chi2_per_dof
    );
    if cal.outliers.is_empty() {
        println!("outliers: none beyond the threshold");
    } else {
        println!("outliers eliminated ({}):", cal.outliers.len());
        for o in &cal.outliers {
            println!(
                "  line {:>5}  {:<6} {:<14} residual {:>10.4} ({:.1} sigma)",
                o.line, o.instrument, o.direction, o.residual, o.deviations
            );
        }
    }
    if let Some(v) = val {
        println!(
            "\nheld-out TCP RMS as measured ({} values): {:.2} µm with the starting parameters \
             (no effects), {:.2} µm calibrated; gain {:.3} (the mean over the values of \
             (|before| - |after|) / |before|: 1 where every error vanished, 0 where none changed)",
            v.values, v.rms_before_um, v.rms_after_um, v.gain
        );
        if let Some(j) = &v.judge {
            println!("{}", rpkm_nodes::words::held_out_judge(j));
        }
    }
}

/// The effects' parameters of the calibrated model (--effects), after the geometry's.
fn print_effects(effects: &[calib::EffectEstimate]) {
    for a in calib::anchored_terms(effects) {
        println!("({})", rpkm_nodes::words::anchored(&a));
    }
    for e in effects.iter().filter(|e| e.physical()) {
        println!(
            "{:<24} {}{}",
            format!("{}.{}", e.effect, e.name),
            rpkm_nodes::words::with_sigma(e.value, e.sigma, &e.unit),
            e.held
                .as_ref()
                .map_or(String::new(), |why| format!("  (not fitted: {why})"))
        );
    }
}

/// The effects' parameters' covariance, with each other and with the geometry's 29: what a
/// quantity derived from several of them needs for its σ (a time constant b/α, say).
fn effects_covariance(cal: &Calibration) -> serde_json::Value {
    let n = cal.covariance_theta.nrows();
    let names: Vec<String> = cal
        .effects
        .iter()
        .map(|e| format!("{}.{}", e.effect, e.name))
        .collect();
    let matrix: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| cal.covariance_theta[(i, j)]).collect())
        .collect();
    let with_geometry: Vec<Vec<f64>> = (0..cal.covariance_p_theta.nrows())
        .map(|i| (0..n).map(|j| cal.covariance_p_theta[(i, j)]).collect())
        .collect();
    json!({
        "names": names,
        "units": cal.effects.iter().map(|e| e.unit.clone()).collect::<Vec<_>>(),
        "matrix": matrix,
        "geometry_names": NAMES,
        "with_geometry": with_geometry,
    })
}

/// The calibration file of `cal`: the fields the readers read typed, the rest of the report
/// (its statistics, the held-out check) as `report`.
fn report_json(cal: &Calibration, val: Option<&Validation>) -> anyhow::Result<CalibrationFile> {
    let mut file = CalibrationFile {
        parameters: cal
            .model
            .params()
            .into_iter()
            .map(|i| (NAMES[i].to_string(), cal.params[i]))
            .collect(),
        // the posterior with its correlations, for a tracker that starts from it (the
        // calibrator node's `geometry_file`): rows and columns in `names` order, mm and rad
        covariance: Some(PosteriorCovariance {
            names: NAMES.iter().map(|n| (*n).to_owned()).collect(),
            matrix: (0..N_PARAMS)
                .map(|i| (0..N_PARAMS).map(|j| cal.covariance[(i, j)]).collect())
                .collect(),
        }),
        identified: Some(
            cal.identified
                .iter()
                .map(IdentifiedEntry::of)
                .collect::<anyhow::Result<_>>()?,
        ),
        effects: cal
            .effects
            .iter()
            .filter(|e| e.physical())
            .map(EffectValue::of)
            .collect::<anyhow::Result<_>>()?,
        ..CalibrationFile::default()
    };
    let mut out = json!({
        "model": cal.model.number(),
        "rms": cal.rms,
        // null where infinite; the words say what that means
        "condition_number": cal.condition_number,
        "condition": rpkm_nodes::words::condition(cal.condition_number, cal.determined),
        "chi2_per_dof": cal.chi2_per_dof,
        "iterations": cal.iterations,
        "rows": cal.rows,
        "outliers": cal.outliers,
    });
    if !cal.effects.is_empty() {
        out["time_constants"] = json!(calib::time_constants(cal));
        out["effects_covariance"] = effects_covariance(cal);
    }
    // this process's own peak (the high-water mark of its memory since it started: a
    // parent's peak does not count, as it does in wait4's ru_maxrss after execve)
    if let Some(mib) = super::peak_resident_mib() {
        out["peak_resident_mib"] = json!(mib);
    }
    if let Some(v) = val {
        out["val_rms_before_um"] = json!(v.rms_before_um);
        out["val_rms_after_um"] = json!(v.rms_after_um);
        out["gain"] = json!(v.gain);
        if let Some(j) = &v.judge {
            out["held_out"] = json!(j);
            out["held_out"]["judge"] = rpkm_nodes::words::held_out(j).into();
        }
    }
    if let serde_json::Value::Object(report) = out {
        file.report = report;
    }
    Ok(file)
}
