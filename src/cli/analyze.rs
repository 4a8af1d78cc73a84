//! `rpkm analyze`: sensitivity (figures 4.10-4.22) and observability (tables 4.4-4.8) of a
//! calibration method, printed, as JSON and as SVG bar charts.

use anyhow::{Context, Result};
use rpkm_core::analysis::{
    self, Method, Observability, ObservabilityOptions, ParamScaling, Pivoting, SensitivityTable,
    StiffnessSeparation, STIFFNESS_RANGE,
};
use rpkm_core::params::{self, Model, Params};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Which analysis.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnalysisKind {
    /// Sensitivity of each measurement direction to each parameter (eq. 3.16, µm or mrad for
    /// 0.1 mm / 1° of parameter variation) on the 231-point grid.
    Sensitivity,
    /// Parameters sorted by observability with the condition number as each is added, the
    /// singular values and the practical rank, on the method's campaign design.
    Observability,
}

/// Parameter scaling of the observability matrix.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalingArg {
    /// Columns × variation range (0.1 mm, 1°).
    Range,
    /// Columns to unit norm.
    ColumnNorm,
}

/// Sorting of the parameters.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PivotingArg {
    /// QR pivoting of V_rᵀ (eq. 3.29) for a first block, then one at a time on the rest.
    Svd,
    /// QR with column pivoting of the scaled Jacobian.
    Qr,
}

fn parse_method(s: &str) -> std::result::Result<Method, String> {
    s.parse::<Method>().map_err(|e| e.to_string())
}

/// Sensitivity or observability analysis of a calibration method at nominal (or given)
/// parameters.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "Methods: lt (laser tracker), kgm (grid encoder), dbb (double \
ball-bar, forward, + second-step q2), li (laser interferometer x and y), psi (laser tracker \
+ platform-angle measurements), self (self-calibration, q2 and q3 followers), currents (the \
drive forces with all four drives position-controlled, no instrument: the stiffness factor is \
analysed beside the parameters, and the output says how much of it the geometry explains; on \
the 231-point grid a machine consistent with the parameters has no preload, so give a recorded \
path with --campaign to see it).\n\n\
Examples:\n  rpkm analyze sensitivity --method lt --model 24 --json out/lt24.json\n  \
rpkm analyze observability --method self --model 24 --block 5 --json out/self24.json\n  \
rpkm analyze observability --method self --model 29 --exclude d1\n  \
rpkm simulate --campaign production --effect preload_elastic --out prod.csv\n  \
rpkm analyze observability --method currents --campaign prod.csv"
)]
pub struct AnalyzeArgs {
    /// sensitivity or observability.
    #[arg(value_enum)]
    pub kind: AnalysisKind,
    /// Calibration method: lt, kgm, dbb, li, psi, self, currents.
    #[arg(long, value_parser = parse_method)]
    pub method: Method,
    /// Geometric model: 24 or 29.
    #[arg(long, default_value_t = 29)]
    pub model: u32,
    /// Parameter file (JSON name -> value); nominal parameters if absent.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Write the result as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Directory of the SVG charts (default: next to the JSON, else ./analysis).
    #[arg(long)]
    pub svg_dir: Option<PathBuf>,
    /// Observability: parameter scaling.
    #[arg(long, value_enum, default_value = "range")]
    pub scaling: ScalingArg,
    /// Observability: how parameters are sorted.
    #[arg(long, value_enum, default_value = "svd")]
    pub pivoting: PivotingArg,
    /// Observability: size of the first block of the SVD pivoting (default: the practical
    /// rank; 5 reproduces table 4.7).
    #[arg(long)]
    pub block: Option<usize>,
    /// Observability: practical-rank tolerance on the weighted, range-scaled Jacobian.
    #[arg(long, default_value_t = 1.0)]
    pub tau: f64,
    /// Observability: parameters left out, comma-separated (e.g. d1).
    #[arg(long, value_delimiter = ',')]
    pub exclude: Vec<String>,
    /// `--method currents` only: analyse this recorded path (a campaign CSV; its poses with
    /// all four drives position-controlled, at their recorded positions and forces) instead
    /// of the 231-point grid.
    #[arg(long)]
    pub campaign: Option<PathBuf>,
}

/// The rows of the analysis: the method's design, or for the currents a recorded path.
fn rows_of(
    args: &AnalyzeArgs,
    p: &Params,
    model: Model,
    second_step: bool,
) -> Result<Vec<rpkm_core::obs::Residual>> {
    let Some(path) = &args.campaign else {
        let design = if second_step {
            args.method.sensitivity_design()
        } else {
            args.method.design()
        };
        return Ok(analysis::design_rows(
            &design,
            p,
            model,
            second_step && args.method.has_second_step(),
        )?);
    };
    if args.method != Method::Currents {
        return Err(super::bad_input(format!(
            "--campaign {}: a recorded path is analysed for --method currents only",
            path.display()
        )));
    }
    let c = rpkm_nodes::input::read_campaign(path)?;
    analysis::currents_rows(&c, p).with_context(|| format!("{}", path.display()))
}

/// Run `rpkm analyze`.
pub fn run(args: &AnalyzeArgs) -> Result<()> {
    let model = Model::from_number(args.model)
        .ok_or_else(|| super::bad_input(format!("--model {}: expected 24 or 29", args.model)))?;
    let p = match &args.params {
        Some(path) => super::read_params(path)?,
        None => Params::nominal(),
    };
    let svg_dir = args.svg_dir.clone().unwrap_or_else(|| {
        args.json
            .as_ref()
            .and_then(|j| j.parent().map(Path::to_path_buf))
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or_else(|| PathBuf::from("analysis"))
    });
    std::fs::create_dir_all(&svg_dir).with_context(|| format!("creating {}", svg_dir.display()))?;
    let stem = format!(
        "{}_{}_{}",
        kind_name(args.kind),
        args.method,
        model.number()
    );
    match args.kind {
        AnalysisKind::Sensitivity => {
            let rows = rows_of(args, &p, model, true)?;
            let t = analysis::sensitivity_of_rows(&rows, args.method, model);
            say(&sensitivity_text(&t));
            let svg = sensitivity_svg(&t);
            let path = svg_dir.join(format!("{stem}.svg"));
            std::fs::write(&path, svg).with_context(|| format!("writing {}", path.display()))?;
            say(&format!("chart: {}\n", path.display()));
            if let Some(j) = &args.json {
                super::write_json(j, &sensitivity_json(&t))?;
            }
        }
        AnalysisKind::Observability => {
            let mut exclude = Vec::new();
            for name in &args.exclude {
                exclude.push(params::index_of(name).ok_or_else(|| {
                    super::bad_input(format!("--exclude: unknown parameter `{name}`"))
                })?);
            }
            let opts = ObservabilityOptions {
                scaling: match args.scaling {
                    ScalingArg::Range => ParamScaling::Range,
                    ScalingArg::ColumnNorm => ParamScaling::ColumnNorm,
                },
                pivoting: match args.pivoting {
                    PivotingArg::Svd => Pivoting::SingularVectors,
                    PivotingArg::Qr => Pivoting::Jacobian,
                },
                block: args.block,
                tau: args.tau,
                ..Default::default()
            };
            let rows = rows_of(args, &p, model, false)?;
            let o = analysis::observability_of_rows(&rows, args.method, model, &exclude, &opts);
            say(&observability_text(&o));
            let path = svg_dir.join(format!("{stem}.svg"));
            std::fs::write(&path, observability_svg(&o))
                .with_context(|| format!("writing {}", path.display()))?;
            say(&format!("chart: {}\n", path.display()));
            if let Some(j) = &args.json {
                super::write_json(j, &observability_json(&o))?;
            }
        }
    }
    Ok(())
}

/// Print to stdout; a closed pipe (`| head`) ends the output quietly.
fn say(text: &str) {
    use std::io::Write;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}

fn kind_name(k: AnalysisKind) -> &'static str {
    match k {
        AnalysisKind::Sensitivity => "sensitivity",
        AnalysisKind::Observability => "observability",
    }
}

/// The sensitivity table as text: one line per parameter, one column per direction.
pub fn sensitivity_text(t: &SensitivityTable) -> String {
    let mut s = format!(
        "sensitivity, method {}, model {} (2-norm mean over the points, per 0.1 mm / 1°)\n",
        t.method, t.model
    );
    let _ = write!(s, "{:<10}", "parameter");
    for d in &t.directions {
        let _ = write!(s, " {:>16}", format!("{} [{}]", d.name, d.unit));
    }
    s += "\n";
    for (k, p) in t.parameters.iter().enumerate() {
        let _ = write!(s, "{p:<10}");
        for v in &t.values[k] {
            let _ = write!(s, " {v:>16.3}");
        }
        s += "\n";
    }
    s
}

/// Sensitivity JSON: method, model, directions (name, instrument, unit, rows) and
/// `values`: for each parameter an object direction -> value.
pub fn sensitivity_json(t: &SensitivityTable) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = t
        .parameters
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let mut m = serde_json::Map::new();
            m.insert("parameter".into(), p.clone().into());
            for (d, v) in t.directions.iter().zip(&t.values[k]) {
                m.insert(d.name.clone(), (*v).into());
            }
            serde_json::Value::Object(m)
        })
        .collect();
    serde_json::json!({
        "kind": "sensitivity",
        "method": t.method.as_str(),
        "model": t.model,
        "directions": t.directions,
        "parameters": t.parameters,
        "values": rows,
    })
}

/// Grouped bars per direction (figures 4.10-4.22); µm and mrad directions in separate
/// panels stacked in one SVG would mix axes, so ψ directions go to their own chart appended
/// below the first.
pub fn sensitivity_svg(t: &SensitivityTable) -> String {
    let mut out = String::new();
    for unit in ["µm", "mrad", "N"] {
        let series: Vec<(String, Vec<f64>)> = t
            .directions
            .iter()
            .enumerate()
            .filter(|(_, d)| d.unit == unit)
            .map(|(di, d)| {
                (
                    format!("d{}", d.name),
                    t.values.iter().map(|row| row[di]).collect(),
                )
            })
            .collect();
        if series.is_empty() {
            continue;
        }
        let title = format!(
            "Sensitivity, {} and model {}{}",
            t.method,
            t.model,
            if unit == "mrad" { " (angle)" } else { "" }
        );
        let svg = crate::plot::bar_chart(
            &title,
            &format!("sensitivity ({unit})"),
            &t.parameters,
            &series,
            &crate::plot::BarOptions::default(),
        );
        if out.is_empty() {
            out = svg;
        } else {
            // two standalone charts: keep the first and add the second after it as a
            // separate document would be invalid XML, so wrap both in one outer svg
            out = wrap_vertically(&out, &svg);
        }
    }
    out
}

fn svg_size(svg: &str) -> (f64, f64) {
    let attr = |name: &str| -> f64 {
        let key = format!("{name}=\"");
        svg.find(&key)
            .and_then(|i| {
                let rest = &svg[i + key.len()..];
                rest.find('"').and_then(|j| rest[..j].parse().ok())
            })
            .unwrap_or(400.0)
    };
    (attr("width"), attr("height"))
}

fn wrap_vertically(a: &str, b: &str) -> String {
    let (wa, ha) = svg_size(a);
    let (wb, hb) = svg_size(b);
    let strip = |s: &str| -> String {
        let s = s.trim_start();
        match s.strip_prefix("<?xml") {
            Some(rest) => rest.split_once("?>").map_or(s, |(_, r)| r).to_string(),
            None => s.to_string(),
        }
    };
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{}\" height=\"{}\">\n<g>{}</g>\n<g transform=\"translate(0,{})\">{}</g>\n</svg>\n",
        wa.max(wb),
        ha + hb,
        strip(a),
        ha,
        strip(b)
    )
}

/// The observability result as text.
pub fn observability_text(o: &Observability) -> String {
    let mut s = format!(
        "observability, method {}, model {}: {} rows, practical rank {} (tau = {}), condition number of all columns {:.3e}\n",
        o.method, o.model, o.rows, o.practical_rank, o.options.tau, o.condition_number
    );
    let _ = writeln!(s, "{:>3} {:<10} {:>14}", "#", "parameter", "condition");
    for (k, e) in o.order.iter().enumerate() {
        let _ = writeln!(
            s,
            "{:>3} {:<10} {:>14}",
            k + 1,
            e.parameter,
            fmt_cond(e.condition_number)
        );
    }
    s += "singular values (weighted, range-scaled):";
    for v in &o.singular_values {
        let _ = write!(s, " {v:.3e}");
    }
    s += "\n";
    if let Some(k) = &o.stiffness {
        s += &stiffness_text(k);
    }
    s
}

/// What the rows say of the stiffness factor beside the geometry.
fn stiffness_text(k: &StiffnessSeparation) -> String {
    if !(k.column_norm > 1e-3) {
        return "stiffness_factor: no preload in these rows (a machine consistent with the \
                parameters): the forces are zero whatever the stiffness; analyse a recorded \
                path (--campaign)\n"
            .to_owned();
    }
    format!(
        "stiffness_factor: column {:.3e} (in σ per 10 %), {:.4} % of it explained by the \
         parameters (scaling the geometry's distance from the controller's scales the forces \
         alike); with the geometry free the rows give it σ = {:.3e} (relative): {}\n",
        k.column_norm,
        100.0 * k.explained(),
        k.sigma_free(),
        if k.sigma_free() < STIFFNESS_RANGE / 3.0 {
            "separable"
        } else {
            "not separable from the geometry by these rows alone (an instrument's rows or a \
             stated stiffness fix it)"
        }
    )
}

fn fmt_cond(c: f64) -> String {
    if !c.is_finite() {
        "inf".into()
    } else if c < 1000.0 {
        format!("{c:.3}")
    } else {
        format!("{c:.3e}")
    }
}

/// Observability JSON: `order` is the sorted list of {parameter, condition_number}
/// (null where infinite), with the singular values and the practical rank.
pub fn observability_json(o: &Observability) -> serde_json::Value {
    let order: Vec<serde_json::Value> = o
        .order
        .iter()
        .map(|e| {
            serde_json::json!({
                "parameter": e.parameter,
                "condition_number": if e.condition_number.is_finite() {
                    serde_json::Value::from(e.condition_number)
                } else {
                    serde_json::Value::Null
                },
            })
        })
        .collect();
    serde_json::json!({
        "kind": "observability",
        "method": o.method.as_str(),
        "model": o.model,
        "options": o.options,
        "rows": o.rows,
        "order": order,
        "singular_values": o.singular_values,
        "practical_rank": o.practical_rank,
        "stiffness": o.stiffness.map(|k| serde_json::json!({
            "column_norm": k.column_norm,
            "independent_norm": k.independent_norm,
            "explained": if k.explained().is_finite() { serde_json::Value::from(k.explained()) } else { serde_json::Value::Null },
            "sigma_free": if k.sigma_free().is_finite() { serde_json::Value::from(k.sigma_free()) } else { serde_json::Value::Null },
        })),
        "condition_number": if o.condition_number.is_finite() {
            serde_json::Value::from(o.condition_number)
        } else {
            serde_json::Value::Null
        },
    })
}

/// Condition number as each parameter is added, on a log axis.
pub fn observability_svg(o: &Observability) -> String {
    let cats: Vec<String> = o.order.iter().map(|e| e.parameter.clone()).collect();
    let vals: Vec<f64> = o.order.iter().map(|e| e.condition_number).collect();
    crate::plot::bar_chart(
        &format!("Observability, {} and model {}", o.method, o.model),
        "condition number",
        &cats,
        &[("condition number".to_string(), vals)],
        &crate::plot::BarOptions { log: true },
    )
}
