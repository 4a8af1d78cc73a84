//! igm/fgm/rgm round trips over the workspace with random parameter errors, and the analytic
//! sensitivities against central finite differences.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

use rand::{rngs::StdRng, Rng, SeedableRng};
use rpkm_core::geometry::{self, Subsystem};
use rpkm_core::params::{unit, Model, Params, Unit, N_PARAMS};

/// Nominal plus uniform errors up to 0.5 mm and 1 mrad.
fn perturbed(rng: &mut StdRng) -> Params {
    let mut p = Params::nominal();
    for i in 0..N_PARAMS {
        p[i] += match unit(i) {
            Unit::Mm => rng.gen_range(-0.5..0.5),
            Unit::Rad => rng.gen_range(-1e-3..1e-3),
        };
    }
    p
}

fn random_tcp(rng: &mut StdRng) -> (f64, f64) {
    (rng.gen_range(-150.0..150.0), rng.gen_range(700.0..2700.0))
}

#[test]
fn igm_fgm_round_trips_on_10000_poses() {
    let mut rng = StdRng::seed_from_u64(7);
    let mut worst = 0.0f64;
    let mut max_iter = 0;
    for n in 0..10_000 {
        let model = if n % 2 == 0 { Model::M24 } else { Model::M29 };
        let p = perturbed(&mut rng);
        let (x, y) = random_tcp(&mut rng);
        let inv = geometry::igm(&p, model, x, y).expect("igm in the workspace");
        let q = inv.q();
        max_iter = max_iter.max(inv.iterations);
        for sub in Subsystem::VIABLE {
            let Subsystem::Actuators(a, b) = sub else {
                unreachable!()
            };
            let fwd = geometry::solve(&p, model, sub, [q[a], q[b]])
                .unwrap_or_else(|e| panic!("{sub} at ({x:.1}, {y:.1}) {model}: {e}"));
            max_iter = max_iter.max(fwd.iterations);
            worst = worst.max((fwd.x() - x).abs()).max((fwd.y() - y).abs());
            for (fq, qi) in fwd.q().iter().zip(&q) {
                worst = worst.max((fq - qi).abs());
            }
        }
        let r = geometry::rgm(&p, model, q[0], q[3]).expect("rgm");
        worst = worst.max((r[0] - q[1]).abs()).max((r[1] - q[2]).abs());
    }
    assert!(worst < 1e-9, "worst round-trip error {worst:e} mm");
    assert!(max_iter <= 6, "a Newton solve needed {max_iter} iterations");
}

#[test]
fn model_24_data_has_constant_platform_angle() {
    let p = Params::nominal();
    for &(x, y) in &[(-150.0, 700.0), (150.0, 2700.0), (37.0, 1234.0)] {
        let s = geometry::igm(&p, Model::M24, x, y).expect("igm");
        assert_eq!(s.psi(), p[rpkm_core::params::GAMMA2]);
    }
}

#[test]
fn sensitivities_match_finite_differences() {
    let mut rng = StdRng::seed_from_u64(11);
    for model in [Model::M24, Model::M29] {
        for sub in [
            Subsystem::Tcp,
            Subsystem::Actuators(0, 3),
            Subsystem::Actuators(2, 3),
            Subsystem::Actuators(1, 2),
            Subsystem::Actuators(0, 1),
        ] {
            let p = perturbed(&mut rng);
            let (x, y) = random_tcp(&mut rng);
            let inv = geometry::igm(&p, model, x, y).expect("igm");
            let known = match sub {
                Subsystem::Tcp => [x, y],
                Subsystem::Actuators(a, b) => [inv.q()[a], inv.q()[b]],
            };
            let sol = geometry::solve(&p, model, sub, known).expect("solve");
            let sens = geometry::sensitivity(&p, model, sub, &sol).expect("sensitivity");
            for k in 0..N_PARAMS {
                let h = if unit(k) == Unit::Rad { 1e-7 } else { 1e-5 };
                let (mut pp, mut pm) = (p, p);
                pp[k] += h;
                pm[k] -= h;
                let cp = geometry::solve(&pp, model, sub, known).expect("solve +").c;
                let cm = geometry::solve(&pm, model, sub, known).expect("solve -").c;
                for v in 0..7 {
                    let fd = (cp[v] - cm[v]) / (2.0 * h);
                    let an = sens.dc_dp[(v, k)];
                    assert!(
                        (fd - an).abs() < 1e-5 * (1.0 + an.abs()),
                        "{model} {sub} d c{v}/d p{k}: fd {fd} analytic {an}"
                    );
                }
            }
            for j in 0..2 {
                let h = 1e-5;
                let (mut kp, mut km) = (known, known);
                kp[j] += h;
                km[j] -= h;
                let cp = geometry::solve(&p, model, sub, kp).expect("solve +").c;
                let cm = geometry::solve(&p, model, sub, km).expect("solve -").c;
                for v in 0..7 {
                    let fd = (cp[v] - cm[v]) / (2.0 * h);
                    let an = sens.dc_dk[(v, j)];
                    assert!(
                        (fd - an).abs() < 1e-5 * (1.0 + an.abs()),
                        "{model} {sub} d c{v}/d k{j}: fd {fd} analytic {an}"
                    );
                }
            }
        }
    }
}

#[test]
fn unreachable_and_non_finite_are_typed_errors() {
    let p = Params::nominal();
    assert!(matches!(
        geometry::igm(&p, Model::M29, 5000.0, 1700.0),
        Err(geometry::GeometryError::Unreachable { .. })
    ));
    assert!(matches!(
        geometry::igm(&p, Model::M29, f64::NAN, 1700.0),
        Err(geometry::GeometryError::NonFinite)
    ));
    assert!(geometry::fgm(&p, Model::M24, 0.0, 1e5).is_err());
}
