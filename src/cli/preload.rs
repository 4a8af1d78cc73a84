//! `rpkm preload`: rod forces, drive forces and redundancy currents of the elasto-geometric
//! model at one pose, with optional offsets on the actuators.

use anyhow::{bail, Context, Result};
use rpkm_core::elastic::{offset_effect, Stiffness, NOMINAL_DRIVE_FORCE_N};
use rpkm_core::params::{Model, Params};
use std::path::PathBuf;

/// Internal preload at one pose: the spring elasto-geometric model with all four drives
/// position-controlled at igm(params) + offsets.
///
/// Example:
///   rpkm preload --params calibrated.json --at 0,1700 --offset q3=0.4 --json preload.json
/// prints each rod's force, each drive's force and current, and the TCP displacement the
/// offsets cause.
#[derive(clap::Args, Debug, Clone)]
#[command(
    after_help = "A params JSON file maps parameter names (l1, xa1r, ..., gamma1) to \
values in mm/rad; missing names keep their nominal value.\n\n\
Example:\n  rpkm preload --params calibrated.json --at 0,1700 --offset q3=0.4 --json preload.json"
)]
pub struct PreloadArgs {
    /// Parameter file (JSON object name -> value); nominal parameters if absent.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// TCP position X,Y in mm.
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        required = true
    )]
    pub at: Vec<f64>,
    /// Offsets on the actuators, qN=MM, comma-separated (e.g. q2=0.2,q3=-0.2).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub offset: Vec<String>,
    /// Write the result as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Scale every stiffness (1 = default 97.7 kN/mm rods, rigid carriers).
    #[arg(long, default_value_t = 1.0)]
    pub stiffness_factor: f64,
}

fn parse_offsets(items: &[String]) -> Result<[f64; 4]> {
    let mut out = [0.0; 4];
    for item in items.iter().filter(|s| !s.trim().is_empty()) {
        let (name, v) = item
            .split_once('=')
            .with_context(|| format!("offset {item:?}: expected qN=MM"))?;
        let i = match name.trim() {
            "q1" => 0,
            "q2" => 1,
            "q3" => 2,
            "q4" => 3,
            other => {
                return Err(super::bad_input(format!(
                    "offset {item:?}: unknown actuator {other:?} (q1..q4)"
                )))
            }
        };
        out[i] = v
            .trim()
            .parse()
            .with_context(|| format!("offset {item:?}: {v:?} is not a number"))?;
    }
    Ok(out)
}

pub fn run(args: &PreloadArgs) -> Result<()> {
    let p = match &args.params {
        Some(path) => super::read_params(path)?,
        None => Params::nominal(),
    };
    let [x, y] = args.at[..] else {
        bail!("--at needs X,Y");
    };
    let offsets = parse_offsets(&args.offset)?;
    let k = Stiffness::default().scaled(args.stiffness_factor);
    let plan = offset_effect(&p, &k, Model::M29, x, y, offsets)
        .with_context(|| format!("elasto-geometric model at ({x}, {y}) mm"))?;
    let eq = &plan.equilibrium;
    println!("pose ({x}, {y}) mm, offsets q1..q4 {offsets:?} mm");
    println!(
        "TCP displacement ({:.4}, {:.4}) mm, platform angle {:.3e} rad",
        plan.tcp_displacement[0], plan.tcp_displacement[1], plan.psi_displacement
    );
    for (i, f) in eq.rod_force.iter().enumerate() {
        println!("rod {}   force {:>10.1} N (tension +)", i + 1, f);
    }
    let current = eq.current();
    for (i, f) in eq.drive_force.iter().enumerate() {
        println!(
            "drive q{} force {:>10.1} N  current {:>7.1} % of {NOMINAL_DRIVE_FORCE_N} N",
            i + 1,
            f,
            current[i]
        );
    }
    if let Some(path) = &args.json {
        let json = serde_json::json!({
            "at": [x, y],
            "offsets": offsets,
            "plan": plan,
            "current_percent": current,
        });
        super::write_json(path, &json)?;
    }
    Ok(())
}
