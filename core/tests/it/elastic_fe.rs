//! The finite-element model (`elastic::fe`): agreement with the spring model where both
//! describe the same machine (pinned rods, near-rigid frame), zero answers for compatible
//! inputs, linearity and sign, equilibrium of the platform and the carriers, the two ways of
//! imposing the incompatibility, and the relations that must hold in the comparison of all
//! redundant forward models (docs/elastic-methods.md).

use rpkm_core::elastic::fe::{
    compare_methods, fe_solve, FeEquilibrium, FeError, FeMethod, FeStiffness, RedundantModel,
    RodEndJoint, Section,
};
use rpkm_core::elastic::{
    fegm, platform_balance, Equilibrium, Followers, Stiffness, ALL_ACTIVE, FOLLOWERS_23,
};
use rpkm_core::geometry::{carrier_joint, fgm, igm, platform_joint, rgm};
use rpkm_core::params::{self, Model, Params, N_PARAMS, RODS};

const POSES: [(f64, f64); 4] = [
    (0.0, 1700.0),
    (100.0, 1000.0),
    (-150.0, 2700.0),
    (150.0, 700.0),
];
const METHODS: [FeMethod; 2] = [FeMethod::ThermoMechanical, FeMethod::ActuatorDisplacements];

fn compatible_q(p: &Params, x: f64, y: f64) -> [f64; 4] {
    igm(p, Model::M29, x, y).expect("igm").q()
}

/// A machine with errors on every parameter (deterministic; as in core/tests/it/elastic_spring.rs).
fn perturbed() -> Params {
    let mut p = Params::nominal();
    for i in 0..N_PARAMS {
        let s = ((i * 7919 % 97) as f64 / 97.0 - 0.5) * 2.0;
        p[i] += match params::unit(i) {
            params::Unit::Mm => 0.1 * s,
            params::Unit::Rad => 2e-4 * s,
        };
    }
    p
}

fn amax(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

/// With pinned rods and a platform and carriers 10⁴ times stiffer than the default, the frame
/// is the spring model's: rods as axial springs of E·A/L = k. Drive forces, rod forces and the
/// TCP displacement from the rigid pose (fegm − fgm(q1, q4)) agree to 1 %, by both methods.
#[test]
fn stiff_frame_with_pinned_rods_agrees_with_the_spring_model() {
    let k_fe = FeStiffness::default().with_stiff_frame(1e4);
    for p in [Params::nominal(), perturbed()] {
        for (x, y) in POSES {
            let q = compatible_q(&p, x, y);
            let q = [q[0], q[1] + 0.02, q[2] + 0.05, q[3]];
            let sp = fegm(&p, &Stiffness::default(), q, ALL_ACTIVE).expect("spring");
            let rigid = fgm(&p, Model::M29, q[0], q[3]).expect("fgm");
            let d_sp = [sp.x - rigid.x(), sp.y - rigid.y(), sp.psi - rigid.psi()];
            for m in METHODS {
                let fe = fe_solve(&p, &k_fe, q, ALL_ACTIVE, m).expect("fe");
                let at = format!("({x}, {y}) {m:?}: fe {fe:?}\nspring {sp:?}");
                let f_tol = 0.01 * amax(&sp.drive_force);
                assert!(max_diff(&fe.drive_force, &sp.drive_force) < f_tol, "{at}");
                assert!(
                    max_diff(&fe.rod_force, &sp.rod_force) < 0.01 * amax(&sp.rod_force),
                    "{at}"
                );
                let d_tol = 0.01 * d_sp[0].hypot(d_sp[1]);
                assert!(
                    max_diff(&fe.tcp_displacement[..2], &d_sp[..2]) < d_tol,
                    "{at}"
                );
                assert!((fe.tcp_displacement[2] - d_sp[2]).abs() < 0.01 * d_sp[2].abs());
                // the mesh lies on the same rigid pose the spring model's TCP moves from
                assert!(max_diff(&fe.reference, &[rigid.x(), rigid.y(), rigid.psi()]) < 1e-9);
            }
        }
    }
}

/// The drives' along-guide compliance enters as the spring model's carrier springs do.
#[test]
fn compliant_drives_agree_with_the_spring_models_carrier_springs() {
    let spring = Stiffness {
        carrier: [Some(40_000.0), Some(25_000.0), None, Some(60_000.0)],
        ..Stiffness::default()
    };
    let k_fe = FeStiffness::matching(&spring).with_stiff_frame(1e4);
    let p = perturbed();
    let q = compatible_q(&p, -40.0, 1300.0);
    let q = [q[0], q[1] - 0.1, q[2] + 0.3, q[3]];
    let sp = fegm(&p, &spring, q, ALL_ACTIVE).expect("spring");
    let stiff_drives = fegm(&p, &Stiffness::default(), q, ALL_ACTIVE).expect("spring");
    for m in METHODS {
        let fe = fe_solve(&p, &k_fe, q, ALL_ACTIVE, m).expect("fe");
        assert!(
            max_diff(&fe.drive_force, &sp.drive_force) < 0.01 * amax(&sp.drive_force),
            "{m:?}: {:?} vs {:?}",
            fe.drive_force,
            sp.drive_force
        );
    }
    // and compliance matters here: the forces are clearly not the rigid drives' ones
    assert!(max_diff(&sp.drive_force, &stiff_drives.drive_force) > 0.1 * amax(&sp.drive_force));
}

/// Compatible parameters (or followers that slide where the rods fit): no force, no
/// displacement, by both methods, whatever the joints.
#[test]
fn compatible_inputs_give_no_force_and_no_displacement() {
    for p in [Params::nominal(), perturbed()] {
        for (x, y) in POSES {
            let q = compatible_q(&p, x, y);
            let [q2, q3] = rgm(&p, Model::M29, q[0], q[3]).expect("rgm");
            let cases: [([f64; 4], Followers); 3] = [
                ([q[0], q2, q3, q[3]], ALL_ACTIVE),
                ([q[0], q2, q3, q[3]], FOLLOWERS_23),
                ([q[0], q2 + 0.3, q3 - 0.2, q[3]], FOLLOWERS_23),
            ];
            for (qq, fol) in cases {
                for joint in [RodEndJoint::Pinned, RodEndJoint::Rigid] {
                    let k = FeStiffness {
                        joint,
                        ..FeStiffness::default()
                    };
                    for m in METHODS {
                        let fe = fe_solve(&p, &k, qq, fol, m).expect("fe");
                        let at = format!("({x}, {y}) {fol:?} {joint:?} {m:?}: {fe:?}");
                        assert!(amax(&fe.drive_force) < 1e-6, "{at}");
                        assert!(amax(&fe.rod_force) < 1e-6, "{at}");
                        assert!(amax(&fe.tcp_displacement) < 1e-9, "{at}");
                    }
                }
            }
        }
    }
}

/// The linear model: the answer of the actuator-displacements method is linear in the
/// incompatibility (to round-off); the thermo-mechanical method's mesh moves with the
/// commanded carrier, so its answer is linear to first order only: the second order is of the
/// size d/l (0.1 mm / 950 mm ≈ 1e-4; measured 1.3e-4). Both flip sign with the
/// incompatibility.
#[test]
fn forces_scale_linearly_and_flip_sign_with_the_incompatibility() {
    let p = perturbed();
    let q = compatible_q(&p, 30.0, 1500.0);
    let at = |d: f64, m: FeMethod| {
        fe_solve(
            &p,
            &FeStiffness::default(),
            [q[0], q[1], q[2] + d, q[3]],
            ALL_ACTIVE,
            m,
        )
        .expect("fe")
    };
    for (m, tol) in [
        (FeMethod::ActuatorDisplacements, 1e-9),
        (FeMethod::ThermoMechanical, 5e-4),
    ] {
        let (one, two, neg) = (at(0.1, m), at(0.2, m), at(-0.1, m));
        assert!(one.max_current() > 10.0, "{one:?}");
        let f1 = one.drive_force;
        let scale = amax(&f1);
        eprintln!(
            "{m:?}: nonlinearity {:.1e}, asymmetry {:.1e}",
            max_diff(&two.drive_force, &f1.map(|f| 2.0 * f)) / scale,
            max_diff(&neg.drive_force, &f1.map(|f| -f)) / scale
        );
        assert!(
            max_diff(&two.drive_force, &f1.map(|f| 2.0 * f)) < tol * scale,
            "{m:?}"
        );
        assert!(
            max_diff(&neg.drive_force, &f1.map(|f| -f)) < tol * scale,
            "{m:?}"
        );
        for j in 0..4 {
            assert!(
                one.drive_force[j] * neg.drive_force[j] < 0.0,
                "{m:?} drive {j}"
            );
        }
        for i in 0..5 {
            assert!(one.rod_force[i] * neg.rod_force[i] <= 0.0, "{m:?} rod {i}");
        }
        let d1 = one.tcp_displacement;
        let dscale = amax(&d1[..2]);
        assert!(max_diff(&two.tcp_displacement[..2], &[2.0 * d1[0], 2.0 * d1[1]]) < tol * dscale);
        assert!(max_diff(&neg.tcp_displacement[..2], &[-d1[0], -d1[1]]) < tol * dscale);
    }
}

/// The rods' loads on the platform balance (force and moment about the TCP) to 1e-6 N and
/// N·mm. With pinned rods the axial forces alone balance it, checked by the spring module's
/// own balance on the mesh geometry; and each drive holds its carrier against the rods' pull
/// along the guide.
#[test]
fn platform_and_carriers_are_in_equilibrium() {
    let p = perturbed();
    let q = compatible_q(&p, -70.0, 2100.0);
    let q = [q[0], q[1] + 0.15, q[2] - 0.25, q[3]];
    for joint in [
        RodEndJoint::Pinned,
        RodEndJoint::Rotational(5e7),
        RodEndJoint::Rigid,
    ] {
        let k = FeStiffness {
            joint,
            ..FeStiffness::default()
        };
        for m in METHODS {
            let fe = fe_solve(&p, &k, q, ALL_ACTIVE, m).expect("fe");
            let b = fe.platform_balance;
            assert!(amax(&b) < 1e-6, "{joint:?} {m:?}: {b:?}");
            assert!(fe.max_current() > 20.0, "{fe:?}");
            if joint == RodEndJoint::Pinned {
                axial_forces_balance(&p, &fe);
            }
        }
    }
}

fn axial_forces_balance(p: &Params, fe: &FeEquilibrium) {
    let [x, y, psi] = fe.reference;
    let c = fe.reference_carrier;
    let mesh = Equilibrium {
        x,
        y,
        psi,
        carrier: c,
        rod_force: fe.rod_force,
        drive_force: fe.drive_force,
        iterations: 0,
    };
    let b = platform_balance(p, &mesh);
    assert!(amax(&b) < 1e-6, "axial balance {b:?}");
    let mut pull = [0.0; 4];
    for (i, rod) in RODS.iter().enumerate() {
        let a = platform_joint(p, rod, x, y, psi);
        let bj = carrier_joint(p, rod, c[rod.actuator]);
        let u = (a - bj).normalize();
        let (_, e, _) = rpkm_core::geometry::guide_frame(p, rod.guide);
        // a rod in tension pulls its carrier towards the platform: the drive pushes back
        pull[rod.actuator] -= fe.rod_force[i] * u.dot(&e);
    }
    assert!(
        max_diff(&pull, &fe.drive_force) < 1e-6,
        "{pull:?} {:?}",
        fe.drive_force
    );
}

/// The two methods agree where they should: with revolute joints, up to the geometric
/// second order of the misfit (the thermo-mechanical mesh sits at the commanded carrier, the
/// other at the fitting one), so the gap shrinks tenfold when the incompatibility does. With
/// welded rod ends they differ at first order: displacing a carrier along its guide also turns
/// the rod, which then bends, while an initial strain only lengthens it.
#[test]
fn thermo_mechanical_and_actuator_displacements_agree_with_revolute_joints() {
    let p = perturbed();
    let gap = |joint: RodEndJoint, d: f64, x: f64, y: f64| -> f64 {
        let k = FeStiffness {
            joint,
            drive: [None, Some(50_000.0), None, None],
            ..FeStiffness::default()
        };
        let q = compatible_q(&p, x, y);
        let q = [q[0], q[1] + d, q[2] - 0.6 * d, q[3]];
        let th = fe_solve(&p, &k, q, ALL_ACTIVE, FeMethod::ThermoMechanical).expect("th");
        let ad = fe_solve(&p, &k, q, ALL_ACTIVE, FeMethod::ActuatorDisplacements).expect("ad");
        let f = max_diff(&th.drive_force, &ad.drive_force) / amax(&ad.drive_force);
        let u = max_diff(&th.tcp_displacement[..2], &ad.tcp_displacement[..2])
            / amax(&ad.tcp_displacement[..2]);
        f.max(u)
    };
    for (x, y) in POSES {
        let (coarse, fine) = (
            gap(RodEndJoint::Pinned, 0.05, x, y),
            gap(RodEndJoint::Pinned, 0.005, x, y),
        );
        assert!(coarse < 1e-3 && fine < 1e-4, "({x}, {y}) {coarse} {fine}");
        assert!(
            fine < 0.2 * coarse,
            "({x}, {y}) second order: {coarse} {fine}"
        );
        let (rc, rf) = (
            gap(RodEndJoint::Rigid, 0.05, x, y),
            gap(RodEndJoint::Rigid, 0.005, x, y),
        );
        eprintln!(
            "({x}, {y}) relative gap pinned {coarse:.1e} / {fine:.1e}, welded {rc:.1e} / {rf:.1e}"
        );
        assert!(rf > 0.5 * rc && rc < 0.02, "({x}, {y}) welded: {rc} {rf}");
    }
}

/// The default FE stiffness keeps the thesis's calibration: 0.4 mm on q3 at the centre costs
/// about 100 % on the most loaded drive (the frame takes about 1.3 % of the compliance).
#[test]
fn default_fe_stiffness_gives_about_100_percent_for_0_4_mm() {
    let p = Params::nominal();
    let q = compatible_q(&p, 0.0, 1700.0);
    let fe = fe_solve(
        &p,
        &FeStiffness::default(),
        [q[0], q[1], q[2] + 0.4, q[3]],
        ALL_ACTIVE,
        FeMethod::ActuatorDisplacements,
    )
    .expect("fe");
    eprintln!("FE q3 + 0.4 mm: currents {:.1?} %", fe.current());
    assert!(
        fe.max_current() > 96.0 && fe.max_current() < 100.0,
        "{fe:?}"
    );
}

#[test]
fn bad_inputs_are_typed_errors() {
    let p = Params::nominal();
    let q = compatible_q(&p, 0.0, 1700.0);
    let k = FeStiffness::default();
    let all_free = [true; 4];
    assert_eq!(
        fe_solve(&p, &k, q, all_free, FeMethod::ThermoMechanical),
        Err(FeError::NotHeld)
    );
    assert_eq!(
        fe_solve(
            &p,
            &k,
            [f64::NAN, q[1], q[2], q[3]],
            ALL_ACTIVE,
            FeMethod::ThermoMechanical
        ),
        Err(FeError::NonFinite)
    );
    let mut soft = k;
    soft.rod[2] = Section { ea: 1e8, ei: 0.0 };
    assert!(matches!(
        fe_solve(&p, &soft, q, ALL_ACTIVE, FeMethod::ThermoMechanical),
        Err(FeError::BadStiffness { .. })
    ));
    let mut merged = p;
    merged[params::XA5R] = p[params::XA4R];
    merged[params::YA5R] = p[params::YA4R];
    let err = fe_solve(&merged, &k, q, ALL_ACTIVE, FeMethod::ThermoMechanical);
    assert!(
        matches!(
            err,
            Err(FeError::DegenerateBeam { .. } | FeError::Reference(_))
        ),
        "{err:?}"
    );
}

/// The comparison of docs/elastic-methods.md and the relations between its columns: least
/// squares is the spring model with equal rods; the two FE methods agree; the FE model with its
/// default frame is within 3 % of the spring model; the linear FE superposes the l2 and l3
/// errors; the statistical mean, blind to stiffness, is symmetric in l2/l3 at x = 0.
#[test]
fn comparison_of_methods_for_10_um_on_l2_and_l3() {
    let nominal = Params::nominal();
    let (sp, fe) = (Stiffness::default(), FeStiffness::default());
    let um = 0.010;
    for (x, y) in [(0.0, 1700.0), (100.0, 1000.0), (-100.0, 2400.0)] {
        let run = |errors: &[(usize, f64)]| {
            compare_methods(&nominal, &sp, &fe, x, y, errors).expect("compare")
        };
        let l2 = run(&[(params::L2, um)]);
        let l3 = run(&[(params::L3, um)]);
        let both = run(&[(params::L2, um), (params::L3, um)]);
        for c in [&l2, &l3, &both] {
            for r in &c.results {
                eprintln!(
                    "({x}, {y}) {:?}: {:>26} TCP ({:7.3}, {:7.3}) µm {:7.3} µrad forces {:?}",
                    c.errors,
                    r.model.name(),
                    r.tcp_error[0] * 1e3,
                    r.tcp_error[1] * 1e3,
                    r.tcp_error[2] * 1e6,
                    r.drive_force.map(|f| f.map(|v| (v * 10.0).round() / 10.0))
                );
                assert!(r.tcp_error[0].hypot(r.tcp_error[1]) > 1e-3, "{r:?}");
            }
            let get = |m: RedundantModel| c.result(m);
            let (ls, spr) = (
                get(RedundantModel::LeastSquares),
                get(RedundantModel::Spring),
            );
            assert!(max_diff(&ls.tcp_error, &spr.tcp_error) < 1e-9);
            let th = get(RedundantModel::FeThermoMechanical);
            let ad = get(RedundantModel::FeActuatorDisplacements);
            let (fth, fad, fsp) = (
                th.drive_force.expect("th"),
                ad.drive_force.expect("ad"),
                spr.drive_force.expect("sp"),
            );
            let scale = amax(&fsp);
            assert!(max_diff(&fth, &fad) < 1e-3 * scale);
            assert!(max_diff(&th.tcp_error, &ad.tcp_error) < 1e-3 * amax(&ad.tcp_error));
            assert!(max_diff(&fad, &fsp) < 0.03 * scale, "{fad:?} vs {fsp:?}");
            let d = spr.tcp_error[0].hypot(spr.tcp_error[1]);
            assert!(max_diff(&ad.tcp_error[..2], &spr.tcp_error[..2]) < 0.03 * d);
        }
        let ad = |c: &rpkm_core::elastic::fe::Comparison| {
            *c.result(RedundantModel::FeActuatorDisplacements)
        };
        let sum: Vec<f64> = (0..4)
            .map(|j| ad(&l2).drive_force.expect("f")[j] + ad(&l3).drive_force.expect("f")[j])
            .collect();
        let fb = ad(&both).drive_force.expect("f");
        assert!(max_diff(&sum, &fb) < 1e-4 * amax(&fb), "{sum:?} vs {fb:?}");
        if x == 0.0 {
            let (s2, s3) = (
                l2.result(RedundantModel::Statistical).tcp_error,
                l3.result(RedundantModel::Statistical).tcp_error,
            );
            assert!((s2[0] - s3[0]).abs() < 1e-7 && (s2[1] + s3[1]).abs() < 1e-7);
        }
    }
}
