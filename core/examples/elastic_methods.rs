//! Prints the comparison of the redundant forward models (docs/elastic-methods.md) as markdown
//! tables: TCP error, platform angle and drive forces for a 10 µm error on l2, on l3 and on
//! both, with the drives at igm(nominal), at a few workspace poses; then the FE model's
//! variants (frame stiffness, joints) on one case.
//!
//! Run: `cargo run -p rpkm-core --example elastic_methods`

use rpkm_core::elastic::fe::{
    compare_methods, fe_solve, Comparison, FeMethod, FeStiffness, RedundantModel, RodEndJoint,
};
use rpkm_core::elastic::{fegm, Stiffness, ALL_ACTIVE};
use rpkm_core::geometry::igm;
use rpkm_core::params::{self, Model, Params};

const POSES: [(f64, f64); 3] = [(0.0, 1700.0), (100.0, 1000.0), (-100.0, 2400.0)];
const ERROR_MM: f64 = 0.010;

fn case_name(c: &Comparison) -> String {
    c.errors
        .iter()
        .map(|(i, _)| params::NAMES[*i])
        .collect::<Vec<_>>()
        .join(" & ")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let nominal = Params::nominal();
    let (spring, fe) = (Stiffness::default(), FeStiffness::default());
    let cases: [&[(usize, f64)]; 3] = [
        &[(params::L2, ERROR_MM)],
        &[(params::L3, ERROR_MM)],
        &[(params::L2, ERROR_MM), (params::L3, ERROR_MM)],
    ];
    let mut rows = Vec::new();
    for (x, y) in POSES {
        for errors in cases {
            rows.push(compare_methods(&nominal, &spring, &fe, x, y, errors)?);
        }
    }
    print_tcp_table(&rows);
    print_angle_table(&rows);
    print_force_table(&rows);
    print_fe_variants(&nominal)?;
    Ok(())
}

fn header(first: &str) {
    let names: Vec<&str> = RedundantModel::ALL.iter().map(|m| m.name()).collect();
    println!("| pose | +10 µm on | {first}{} |", names.join(" | "));
    println!(
        "|---|---|{}",
        "---|".repeat(names.len() + usize::from(!first.is_empty()))
    );
}

fn print_tcp_table(rows: &[Comparison]) {
    println!("TCP error x, y (µm): predicted − commanded\n");
    header("");
    for c in rows {
        let cells: Vec<String> = c
            .results
            .iter()
            .map(|r| format!("{:.2}, {:.2}", r.tcp_error[0] * 1e3, r.tcp_error[1] * 1e3))
            .collect();
        println!(
            "| ({}, {}) | {} | {} |",
            c.x,
            c.y,
            case_name(c),
            cells.join(" | ")
        );
    }
    println!();
}

fn print_angle_table(rows: &[Comparison]) {
    println!("Platform angle error ψ (µrad)\n");
    header("");
    for c in rows {
        let cells: Vec<String> = c
            .results
            .iter()
            .map(|r| format!("{:.2}", r.tcp_error[2] * 1e6))
            .collect();
        println!(
            "| ({}, {}) | {} | {} |",
            c.x,
            c.y,
            case_name(c),
            cells.join(" | ")
        );
    }
    println!();
}

fn print_force_table(rows: &[Comparison]) {
    println!("Drive forces f1, f2, f3, f4 (N) and the largest redundancy current\n");
    println!("| pose | +10 µm on | spring fegm | FE thermo-mechanical | FE actuator-displacements | max current |");
    println!("|---|---|---|---|---|---|");
    for c in rows {
        let forces = |m: RedundantModel| {
            c.result(m)
                .drive_force
                .map(|f| format!("{:.1}, {:.1}, {:.1}, {:.1}", f[0], f[1], f[2], f[3]))
                .unwrap_or_default()
        };
        let current = c
            .result(RedundantModel::FeActuatorDisplacements)
            .drive_force
            .map_or(0.0, |f| {
                f.iter().fold(0.0_f64, |m, v| m.max(v.abs())) / 8600.0 * 100.0
            });
        println!(
            "| ({}, {}) | {} | {} | {} | {} | {:.1} % |",
            c.x,
            c.y,
            case_name(c),
            forces(RedundantModel::Spring),
            forces(RedundantModel::FeThermoMechanical),
            forces(RedundantModel::FeActuatorDisplacements),
            current
        );
    }
    println!();
}

/// The FE model's own variants at the centre, l3 + 10 µm: what the frame and the joints change.
fn print_fe_variants(nominal: &Params) -> Result<(), Box<dyn std::error::Error>> {
    let (x, y) = (0.0, 1700.0);
    let command = igm(nominal, Model::M29, x, y)?;
    let q = command.q();
    let mut machine = *nominal;
    machine[params::L3] += ERROR_MM;
    println!("FE variants at ({x}, {y}), l3 + 10 µm (actuator-displacements unless noted)\n");
    println!("| model | TCP error x, y (µm) | ψ (µrad) | f1, f2, f3, f4 (N) |");
    println!("|---|---|---|---|");
    let sp = fegm(&machine, &Stiffness::default(), q, ALL_ACTIVE)?;
    let line = |name: &str, pose: [f64; 3], f: [f64; 4]| {
        println!(
            "| {name} | {:.3}, {:.3} | {:.3} | {:.1}, {:.1}, {:.1}, {:.1} |",
            (pose[0] - x) * 1e3,
            (pose[1] - y) * 1e3,
            (pose[2] - command.psi()) * 1e6,
            f[0],
            f[1],
            f[2],
            f[3]
        );
    };
    line("spring fegm", [sp.x, sp.y, sp.psi], sp.drive_force);
    let d = FeStiffness::default();
    let variants: [(&str, FeStiffness, FeMethod); 6] = [
        (
            "FE default (pinned rods)",
            d,
            FeMethod::ActuatorDisplacements,
        ),
        (
            "FE default, thermo-mechanical",
            d,
            FeMethod::ThermoMechanical,
        ),
        (
            "FE platform and carriers ×10⁴ stiffer",
            d.with_stiff_frame(1e4),
            FeMethod::ActuatorDisplacements,
        ),
        (
            "FE welded rod ends, actuator-displacements",
            FeStiffness {
                joint: RodEndJoint::Rigid,
                ..d
            },
            FeMethod::ActuatorDisplacements,
        ),
        (
            "FE welded rod ends, thermo-mechanical",
            FeStiffness {
                joint: RodEndJoint::Rigid,
                ..d
            },
            FeMethod::ThermoMechanical,
        ),
        (
            "FE drives 40 kN/mm along their guides",
            FeStiffness {
                drive: [Some(40_000.0); 4],
                ..d
            },
            FeMethod::ActuatorDisplacements,
        ),
    ];
    for (name, k, m) in variants {
        let e = fe_solve(&machine, &k, q, ALL_ACTIVE, m)?;
        line(name, [e.x, e.y, e.psi], e.drive_force);
    }
    println!();
    Ok(())
}
