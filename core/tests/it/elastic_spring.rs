//! The spring elasto-geometric forward model: rigid limit, balance, signs, sensitivities,
//! default stiffness, compatibility test and preload offsets.

use rpkm_core::elastic::{
    self, baseline, compatibility, fegm, platform_balance, preload_offsets, sensitivity, Stiffness,
    ALL_ACTIVE, DEFAULT_ROD_STIFFNESS_N_PER_MM, FOLLOWERS_23,
};
use rpkm_core::geometry::{fgm, igm, rgm};
use rpkm_core::params::{self, Model, Params, N_PARAMS};

fn compatible_q(p: &Params, x: f64, y: f64) -> [f64; 4] {
    igm(p, Model::M29, x, y).expect("igm").q()
}

/// A machine with errors on every parameter (deterministic).
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

#[test]
fn compatible_parameters_reproduce_the_rigid_fgm() {
    let k = Stiffness::default();
    for p in [Params::nominal(), perturbed()] {
        for (x, y) in [
            (0.0, 1700.0),
            (-150.0, 700.0),
            (150.0, 2700.0),
            (80.0, 1200.0),
        ] {
            let q = compatible_q(&p, x, y);
            let rigid = fgm(&p, Model::M29, q[0], q[3]).expect("fgm");
            let [q2, q3] = rgm(&p, Model::M29, q[0], q[3]).expect("rgm");
            for fol in [ALL_ACTIVE, FOLLOWERS_23] {
                let eq = fegm(&p, &k, [q[0], q2, q3, q[3]], fol).expect("fegm");
                assert!((eq.x - rigid.x()).abs() < 1e-9, "{x} {y} {fol:?}");
                assert!((eq.y - rigid.y()).abs() < 1e-9);
                assert!((eq.psi - rigid.psi()).abs() < 1e-12);
                assert!(eq.drive_force.iter().all(|f| f.abs() < 1e-5), "{eq:?}");
            }
            // Followers: whatever q2, q3 are commanded, the carriers settle on rgm.
            let eq = fegm(&p, &k, [q[0], q2 + 0.3, q3 - 0.2, q[3]], FOLLOWERS_23).expect("f");
            assert!((eq.x - rigid.x()).abs() < 1e-9);
            assert!((eq.carrier[1] - q2).abs() < 1e-9 && (eq.carrier[2] - q3).abs() < 1e-9);
        }
    }
}

#[test]
fn platform_balances_and_forces_flip_with_the_incompatibility() {
    let p = perturbed();
    let k = Stiffness::default();
    let q = compatible_q(&p, 30.0, 1500.0);
    for d in [0.2, -0.2] {
        let eq = fegm(&p, &k, [q[0], q[1], q[2] + d, q[3]], ALL_ACTIVE).expect("fegm");
        let b = platform_balance(&p, &eq);
        assert!(b[0].abs() < 1e-6 && b[1].abs() < 1e-6, "{b:?}");
        assert!(b[2].abs() < 1e-6 * 1e3, "{b:?}");
        // Drive force balance along the guides: Σ drive forces = guide components of rods
        assert!(eq.max_current() > 10.0);
        let neg = fegm(&p, &k, [q[0], q[1], q[2] - d, q[3]], ALL_ACTIVE).expect("fegm");
        for j in 0..4 {
            let (a, b) = (eq.drive_force[j], neg.drive_force[j]);
            assert!(a * b < 0.0, "drive {j}: {a} vs {b}");
            assert!(
                (a + b).abs() < 0.02 * a.abs().max(b.abs()),
                "drive {j}: {a} vs {b}"
            );
        }
        for i in 0..5 {
            assert!(eq.rod_force[i] * neg.rod_force[i] <= 0.0);
        }
    }
}

#[test]
fn compliant_carriers_balance_their_springs() {
    let p = Params::nominal();
    let k = Stiffness {
        carrier: [Some(40_000.0); 4],
        ..Stiffness::default()
    };
    let q = compatible_q(&p, 0.0, 1700.0);
    let qq = [q[0], q[1], q[2] + 0.4, q[3]];
    let eq = fegm(&p, &k, qq, ALL_ACTIVE).expect("fegm");
    for (j, &qj) in qq.iter().enumerate() {
        let spring = -40_000.0 * (eq.carrier[j] - qj);
        assert!((spring - eq.drive_force[j]).abs() < 1e-5, "{j}");
    }
    let rigid = fegm(&p, &Stiffness::default(), qq, ALL_ACTIVE).expect("fegm");
    assert!(eq.max_current() < rigid.max_current());
}

fn fd_check(p: &Params, k: &Stiffness, q: [f64; 4], fol: elastic::Followers) {
    let eq = fegm(p, k, q, fol).expect("fegm");
    let s = sensitivity(p, k, q, fol, &eq).expect("sens");
    let pose = |e: &elastic::Equilibrium| [e.x, e.y, e.psi];
    for j in 0..4 {
        let h = 1e-4;
        let mut qp = q;
        let mut qm = q;
        qp[j] += h;
        qm[j] -= h;
        let (a, b) = (
            pose(&fegm(p, k, qp, fol).expect("+")),
            pose(&fegm(p, k, qm, fol).expect("-")),
        );
        for r in 0..3 {
            let fd = (a[r] - b[r]) / (2.0 * h);
            assert!(
                (fd - s.dpose_dq[(r, j)]).abs() < 1e-6 * (1.0 + fd.abs()),
                "dq{} row {r}: fd {fd} vs {}",
                j + 1,
                s.dpose_dq[(r, j)]
            );
        }
    }
    for i in 0..N_PARAMS {
        let h = match params::unit(i) {
            params::Unit::Mm => 1e-4,
            params::Unit::Rad => 1e-7,
        };
        let mut pp = *p;
        let mut pm = *p;
        pp[i] += h;
        pm[i] -= h;
        let (a, b) = (
            pose(&fegm(&pp, k, q, fol).expect("+")),
            pose(&fegm(&pm, k, q, fol).expect("-")),
        );
        for r in 0..3 {
            let fd = (a[r] - b[r]) / (2.0 * h);
            let an = s.dpose_dp[(r, i)];
            assert!(
                (fd - an).abs() < 1e-5 * (1.0 + fd.abs()),
                "{} row {r}: fd {fd} vs {an}",
                params::NAMES[i]
            );
        }
    }
}

#[test]
fn sensitivities_match_finite_differences() {
    let p = perturbed();
    let q = compatible_q(&p, 40.0, 1300.0);
    let pre = [q[0], q[1] + 0.15, q[2] - 0.1, q[3]];
    fd_check(&p, &Stiffness::default(), pre, ALL_ACTIVE);
    fd_check(&p, &Stiffness::default(), pre, FOLLOWERS_23);
    let soft = Stiffness {
        carrier: [Some(30_000.0), Some(20_000.0), None, Some(50_000.0)],
        ..Stiffness::default()
    };
    fd_check(&p, &soft, pre, ALL_ACTIVE);
}

/// The default stiffness reproduces the thesis: 0.4 mm on one drive ≈ 100 % current.
#[test]
fn default_stiffness_gives_100_percent_for_0_4_mm() {
    let p = Params::nominal();
    let q = compatible_q(&p, 0.0, 1700.0);
    let mut worst: f64 = 0.0;
    for j in [1, 2] {
        let mut qq = q;
        qq[j] += 0.4;
        let eq = fegm(&p, &Stiffness::default(), qq, ALL_ACTIVE).expect("fegm");
        let c = eq.current();
        eprintln!(
            "q{} + 0.4 mm: currents {:.1?} %, rods {:.0?} N (k = {DEFAULT_ROD_STIFFNESS_N_PER_MM} N/mm)",
            j + 1,
            c,
            eq.rod_force
        );
        worst = worst.max(eq.max_current());
    }
    eprintln!("worst {worst:.6}");
    assert!((worst - 100.0).abs() < 1.0, "{worst}");
    {}
}

/// Δq2, Δq3 of opposite sign cost more current than of the same sign (thesis 4.4).
#[test]
fn opposite_signs_cost_more_current() {
    let p = Params::nominal();
    let k = Stiffness::default();
    let q = compatible_q(&p, 0.0, 1700.0);
    let same = fegm(&p, &k, [q[0], q[1] + 0.2, q[2] + 0.2, q[3]], ALL_ACTIVE).expect("s");
    let opp = fegm(&p, &k, [q[0], q[1] + 0.2, q[2] - 0.2, q[3]], ALL_ACTIVE).expect("o");
    eprintln!(
        "same sign: {:.1?} %, opposite: {:.1?} %",
        same.current(),
        opp.current()
    );
    assert!(opp.max_current() > same.max_current());
}

#[test]
fn compatibility_test_and_first_approach() {
    let machine = perturbed();
    let k = Stiffness::default();
    let c = compatibility(&machine, &k, &Params::nominal(), Model::M29, 0.0, 1700.0).expect("c");
    eprintln!(
        "compatibility of nominal params on the perturbed machine: dq2 {:.3} dq3 {:.3} mm, current {:.1?} %",
        c.dq2,
        c.dq3,
        c.active.current()
    );
    let same = compatibility(&machine, &k, &machine, Model::M29, 0.0, 1700.0).expect("c");
    assert!(same.dq2.abs() < 1e-9 && same.dq3.abs() < 1e-9);
    assert!(same.active.max_current() < 1e-6);

    let plan =
        preload_offsets(&machine, &k, Model::M29, 0.0, 1700.0, [1000.0, -1000.0]).expect("plan");
    let f = plan.equilibrium.drive_force;
    assert!(
        (f[1] - 1000.0).abs() < 1e-2 && (f[2] + 1000.0).abs() < 1e-2,
        "{f:?}"
    );
    eprintln!(
        "first approach: offsets q2 {:.4} q3 {:.4} mm for f2 = 1000 N, f3 = -1000 N; TCP moves ({:.4}, {:.4}) mm",
        plan.offsets[1], plan.offsets[2], plan.tcp_displacement[0], plan.tcp_displacement[1]
    );
}

/// Comparison of methods (docs/elastic.md): TCP error for a 10 µm error on l2 or l3 while
/// all four drives hold igm(nominal).
#[test]
fn comparison_of_methods_for_10_um_on_l2_l3() {
    let nominal = Params::nominal();
    let k = Stiffness::default();
    for (x, y) in [(0.0, 1700.0), (100.0, 1000.0)] {
        let q = compatible_q(&nominal, x, y);
        for which in [params::L2, params::L3] {
            let mut m = nominal;
            m[which] += 0.010;
            let rigid = fgm(&m, Model::M29, q[0], q[3]).expect("fgm");
            let st = baseline::statistical(&m, Model::M29, q).expect("stat");
            let ls = baseline::least_squares(&m, q).expect("ls");
            let sp = fegm(&m, &k, q, ALL_ACTIVE).expect("spring");
            eprintln!(
                "({x}, {y}) {} + 10 µm: TCP error µm  fgm(q1,q4) ({:.3}, {:.3})  statistical ({:.3}, {:.3})  least-squares ({:.3}, {:.3})  spring ({:.3}, {:.3}), current {:.1} %",
                params::NAMES[which],
                (rigid.x() - x) * 1e3, (rigid.y() - y) * 1e3,
                (st.x - x) * 1e3, (st.y - y) * 1e3,
                (ls.x - x) * 1e3, (ls.y - y) * 1e3,
                (sp.x - x) * 1e3, (sp.y - y) * 1e3,
                sp.max_current()
            );
            // With equal rod stiffness the spring model is the least-squares model.
            assert!((sp.x - ls.x).abs() < 1e-9 && (sp.y - ls.y).abs() < 1e-9);
        }
    }
}
