//! `rpkm demo`: the story on the embedded default data (bags/demo, made by the twin with a
//! hidden effect): the thesis's simple model against the measurements, where it fails, the
//! test that says something is missing, the effect added, the held-out error falling.

use super::calibrate::validate;
use crate::plot;
use anyhow::Context;
use rpkm_core::calib::{self, Calibration, Options, Selection};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::noise;
use rpkm_core::obs;
use rpkm_core::params::{Model, Params};
use std::fmt::Write as _;
use std::path::PathBuf;

/// The embedded campaign: laser tracker + self-calibration on the twin, with a hidden
/// imperfect parallel-holder (see bags/README.md for the command that made it).
const CAMPAIGN: &str = include_str!("../../../bags/demo/campaign.csv");
const VALIDATION: &str = include_str!("../../../bags/demo/campaign.val.csv");

/// Run the demonstration on the embedded data and write an HTML report.
///
/// Example:
///   rpkm demo --out rpkm-demo && xdg-open rpkm-demo/report.html
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Folder for the report (HTML and SVG plots).
    #[arg(long, default_value = "rpkm-demo")]
    pub out: PathBuf,
}

/// Expected RMS (mm) of the held-out TCP errors if the model were perfect: the laser
/// tracker's noise at the held-out poses (located by the nominal fgm of their actuators).
fn noise_floor_mm(val: &Campaign) -> anyhow::Result<f64> {
    let nominal = Params::nominal();
    let mut var = Vec::new();
    for p in val
        .poses
        .iter()
        .filter(|p| p.instrument == Instrument::Lt && !p.reset)
    {
        let tcp = rpkm_core::geometry::fgm(&nominal, Model::M29, p.q[0], p.q[3])
            .map_err(|e| anyhow::anyhow!("{}:{}: {e}", val.source, p.line))?;
        let cov = noise::lt_covariance(nalgebra::Vector2::new(tcp.x(), tcp.y()));
        var.push(cov[(0, 0)]);
        var.push(cov[(1, 1)]);
    }
    Ok((var.iter().sum::<f64>() / var.len().max(1) as f64).sqrt())
}

fn calibrate(c: &Campaign, model: Model) -> anyhow::Result<Calibration> {
    let opts = Options {
        model,
        selection: Selection::Auto { max_condition: 1e5 },
        ..Default::default()
    };
    calib::calibrate(c, &Params::nominal(), &opts).with_context(|| format!("calibrating {model}"))
}

/// Held-out residual vectors (x, y, dx µm, dy µm) at the absolute TCP of each held-out pose.
fn residual_field(
    val: &Campaign,
    p: &Params,
    model: Model,
) -> anyhow::Result<Vec<(f64, f64, f64, f64)>> {
    let errs = obs::tcp_errors(val, p, model).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut out: Vec<(f64, f64, f64, f64)> = Vec::new();
    for (i, coord, e) in errs {
        let pose = &val.poses[i];
        let tcp = rpkm_core::geometry::fgm(p, model, pose.q[0], pose.q[3])
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        match out.last_mut() {
            Some(last) if coord == "y" && last.0 == tcp.x() && last.1 == tcp.y() => {
                last.3 = 1e3 * e
            }
            _ => out.push((
                tcp.x(),
                tcp.y(),
                if coord == "x" { 1e3 * e } else { 0.0 },
                if coord == "y" { 1e3 * e } else { 0.0 },
            )),
        }
    }
    Ok(out)
}

pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let campaign = Campaign::parse(CAMPAIGN, "bags/demo/campaign.csv")?;
    let val = Campaign::parse(VALIDATION, "bags/demo/campaign.val.csv")?;
    let floor_um = 1e3 * noise_floor_mm(&val)?;
    println!(
        "rpkm demo: {} poses (laser tracker + self-calibration), {} held-out poses",
        campaign.poses.len(),
        val.poses.len()
    );
    println!("held-out noise floor (laser tracker noise at those poses): {floor_um:.1} µm\n");

    println!(
        "1. The thesis's simple model (model 24: perfect parallel-holder) against the measurements"
    );
    let m24 = calibrate(&campaign, Model::M24)?;
    let v24 = validate(&val, &Params::nominal(), &m24.params, Model::M24)?;
    println!(
        "   {} parameters identified, condition number {:.0}",
        m24.identified.len(),
        m24.condition_number
    );
    println!(
        "   held-out RMS {:.1} µm nominal -> {:.1} µm calibrated",
        v24.rms_before_um, v24.rms_after_um
    );
    println!(
        "   chi-square per degree of freedom {:.1}",
        m24.chi2_per_dof
    );

    println!("\n2. Where it fails");
    for r in m24.rms.iter().filter(|r| !r.is_angle) {
        let sigma_hint = if r.instrument == "self" {
            "follower encoders"
        } else {
            "actuator space"
        };
        println!(
            "   {:<5} {:<4} residual RMS {:>8.2} µm ({sigma_hint})",
            r.instrument,
            r.direction,
            1e3 * r.rms_after
        );
    }
    let dof = m24.rows as f64 - m24.identified.len() as f64;
    let z = (m24.chi2_per_dof - 1.0) * (dof / 2.0).sqrt();
    let missing = m24.chi2_per_dof > 1.0 + 3.0 * (2.0 / dof).sqrt();
    println!("   the residual is {}consistent with the instruments' noise (chi-square test, {dof:.0} dof, z = {z:.0})", if missing { "NOT " } else { "" });

    println!("\n3. The missing effect");
    let m29 = calibrate(&campaign, Model::M29)?;
    let v29 = validate(&val, &Params::nominal(), &m29.params, Model::M29)?;
    println!(
        "   parallelogram: the parallel-holder is not perfect (model 24 -> model 29, rod 5 free)"
    );
    println!("   with it: chi-square per dof {:.2}, held-out RMS {:.1} µm -> {:.1} µm (floor {floor_um:.1} µm)", m29.chi2_per_dof, v24.rms_after_um, v29.rms_after_um);
    for id in m29
        .identified
        .iter()
        .filter(|i| i.name.ends_with('5') || i.name.contains("5r"))
    {
        println!(
            "   {:<6} {:>12.4} mm (nominal {:.1}, sigma {:.4})",
            id.name, id.value, id.nominal, id.sigma
        );
    }

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let f24 = residual_field(&val, &m24.params, Model::M24)?;
    let f29 = residual_field(&val, &m29.params, Model::M29)?;
    let q24 = plot::quiver(
        "Held-out TCP residual, model 24 (perfect parallel-holder)",
        &f24,
        "µm",
    );
    let q29 = plot::quiver(
        "Held-out TCP residual, model 29 (parallel-holder identified)",
        &f29,
        "µm",
    );
    let bars = plot::bar_chart(
        "Held-out TCP RMS",
        "RMS (µm)",
        &[
            "nominal".to_string(),
            "model 24".to_string(),
            "model 29".to_string(),
            "noise floor".to_string(),
        ],
        &[(
            "held-out RMS".to_string(),
            vec![
                v24.rms_before_um,
                v24.rms_after_um,
                v29.rms_after_um,
                floor_um,
            ],
        )],
        &plot::BarOptions::default(),
    );
    for (name, svg) in [
        ("residual_model24.svg", &q24),
        ("residual_model29.svg", &q29),
        ("held_out_rms.svg", &bars),
    ] {
        std::fs::write(args.out.join(name), svg).with_context(|| format!("writing {name}"))?;
    }
    let mut html = String::from("<!doctype html><meta charset=\"utf-8\"><title>rpkm demo</title><body style=\"font-family:sans-serif;max-width:1000px\">");
    let _ = write!(
        html,
        "<h1>rpkm demo: model vs measurements</h1><p>{} calibration poses, {} held-out poses. Noise floor {floor_um:.1} µm.</p>\
         <h2>1. Model 24</h2><p>Held-out RMS {:.1} µm → {:.1} µm; χ²/dof {:.1}: the residual is {}consistent with noise.</p>{q24}\
         <h2>2. With the parallel-holder identified (model 29)</h2><p>χ²/dof {:.2}; held-out RMS {:.1} µm.</p>{q29}<h2>Held-out RMS</h2>{bars}</body>",
        campaign.poses.len(), val.poses.len(), v24.rms_before_um, v24.rms_after_um, m24.chi2_per_dof, if missing { "not " } else { "" }, m29.chi2_per_dof, v29.rms_after_um,
    );
    let report = args.out.join("report.html");
    std::fs::write(&report, html).with_context(|| format!("writing {}", report.display()))?;
    println!("\nreport: {}", report.display());
    Ok(())
}
