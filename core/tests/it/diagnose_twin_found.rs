//! Machines of the benchmark that fooled a rule of the diagnosis, rebuilt from their twin's
//! configuration (`rpkm bench discovery --only I --write DIR` prints it in `machine.txt`):
//! each test says which rule and what it said before.

use super::diagnose_twin::{campaigns_of, run, summary};
use rpkm_core::campaign::Instrument;
use rpkm_core::noise::NoiseModel;
use rpkm_twin::{EffectKind, ThermalPhysics, TwinConfig};

/// Rods and frame expanding (10.5 and 6.3 ppm/K) under a thermometer 950 s behind them,
/// measured by a tracker and self-calibration only (the lag class's seed 3, machine 7): the
/// campaign hardly tells the two parts apart. The expansion of every part alone fitted 70 and
/// 55 ppm/K, values no material has, and still disqualified `thermal:rods` (a larger model
/// beat it) and the pair with its lag (the lag added nothing to its prediction): the first
/// diagnosis named nothing. A larger model of unphysical values disqualifies no smaller one,
/// and a member without which the values are unphysical earns its place: the twin's parts
/// with their lag are named, each α within 2σ of the twin's.
#[test]
fn a_lag_that_makes_the_expansion_physical_earns_its_place() {
    let noise = NoiseModel {
        tracker_position: [0.0, -1500.0],
        lt_along_mm: 0.009_231,
        lt_across_mm: 0.011_107,
        lt_across_per_m_mm: 0.001_851,
        kgm_mm: 0.000_626,
        dbb_mm: 0.001_551,
        li_mm: 0.000_792,
        psi_rad: 1.130e-6,
        encoder_mm: 0.000_191_5,
        force_n: 2.578,
        drive_position_mm: 0.000_208,
    };
    let (rods, frame) = (10.52e-6, 6.284e-6);
    let (cal, val, _) = campaigns_of(
        TwinConfig {
            seed: 7_391_960_166_268_775_616,
            effects: vec![(EffectKind::Thermal, 2.6715)],
            noise: Some(noise),
            length_sigma_mm: 0.0820,
            angle_sigma_rad: 1.882e-4,
            thermal: ThermalPhysics {
                rods_per_k: rods,
                frame_per_k: frame,
                scales_per_k: 0.0,
                thermometer_lag_s: 949.8,
                ..Default::default()
            },
            ..Default::default()
        },
        &[Instrument::Lt, Instrument::SelfCal],
    );
    let d = run(&cal, &val, &[]);
    eprintln!("{}", summary(&d));
    assert_eq!(
        d.missing_effects,
        ["thermal:rods+frame", "thermal_lag:rods+frame"],
        "{}",
        summary(&d)
    );
    let named = d
        .trials
        .iter()
        .find(|t| t.added == d.missing_effects)
        .expect("the model named among the trials");
    for (name, twin) in [("alpha_rods", rods), ("alpha_frame", frame)] {
        let p = named
            .params
            .iter()
            .find(|p| p.name == name)
            .unwrap_or_else(|| panic!("{name} fitted"));
        let z = (p.value - twin * 1e6) / p.sigma;
        assert!(
            z.abs() < 2.0,
            "{name} {} ± {} ppm/K, the twin's {}",
            p.value,
            p.sigma,
            twin * 1e6
        );
    }
}
