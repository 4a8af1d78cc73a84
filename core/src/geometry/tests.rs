//! Unit tests of `geometry`.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

use super::closure::{equation_rods, Trig};
use super::fgm::{
    fgm_closed, fgm_ratio_squared, fgm_start, in_assembly_mode, rod5_open, rod5_open_slope,
    rod_in_assembly_mode, settled_psi_fgm,
};
use super::igm::{igm24, igm29, igm_start, WARM_PSI_RAD};
use super::newton::{conditioning_ratio, det5, newton, select_columns, Lu5};
use super::*;
use crate::params::{Model, Params, GAMMA2, N_PARAMS, RODS};
use nalgebra::{SMatrix, Vector2};

/// det5 against nalgebra's LU determinant on random matrices, a singular one, and a
/// permutation (its sign).
#[test]
fn det5_matches_the_lu_determinant() {
    let mut x = 0x2545_f491_4f6c_dd1d_u64;
    for _ in 0..200 {
        let m = SMatrix::<f64, 5, 5>::from_fn(|_, _| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        });
        let (a, b) = (det5(m), m.determinant());
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-3), "{a} vs {b}");
    }
    // the solves too: A X = B for 31 right-hand sides, against nalgebra's LU
    for _ in 0..50 {
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let a = SMatrix::<f64, 5, 5>::from_fn(|_, _| next());
        let b = SMatrix::<f64, 5, 31>::from_fn(|_, _| next());
        let ours = Lu5::new(a).expect("regular").solve(&b);
        let want = a.lu().solve(&b).expect("regular");
        assert!(
            (ours - want).amax() <= 1e-10 * want.amax(),
            "{ours} vs {want}"
        );
        assert!((a * ours - b).amax() < 1e-12, "residual");
    }
    let mut singular = SMatrix::<f64, 5, 5>::identity();
    singular.set_row(4, &singular.row(3).clone_owned());
    assert_eq!(det5(singular), 0.0);
    let mut swap = SMatrix::<f64, 5, 5>::identity();
    swap.swap_rows(0, 3);
    assert_eq!(det5(swap), -1.0);
}

/// The model-29 igm (the closed checks of [`igm29`], else Newton from the rod-5 start)
/// gives what Newton from the model-24 start gives (to 1e-9 mm, both within the solver's
/// tolerance), refuses the poses that refuses, and needs the general solver nowhere in
/// the workspace.
#[test]
fn igm29_start_converges_to_the_same_pose() {
    let mut p = Params::nominal();
    for (k, i) in [0, 3, 7, 12, 20, 24, 26].into_iter().enumerate() {
        p[i] += 0.05 * (k as f64 + 1.0);
    }
    let (mut solved, mut closed, mut steps_old, mut steps_new) = (0, 0, 0, 0);
    for i in 0..31 {
        for j in 0..31 {
            let (x, y) = (-300.0 + 20.0 * f64::from(i), 500.0 + 80.0 * f64::from(j));
            let new = solve(&p, Model::M29, Subsystem::Tcp, [x, y]);
            let old = igm_start(&p, x, y)
                .and_then(|c| newton(&p, Model::M29, Subsystem::Tcp, c))
                .and_then(|sol| {
                    let t = Trig::new(&p, &sol.c);
                    match RODS
                        .iter()
                        .find(|r| !rod_in_assembly_mode(&p, r, &sol.c, &t))
                    {
                        Some(rod) => Err(GeometryError::AssemblyMode { rod: rod.number }),
                        None => Ok(sol),
                    }
                });
            match (new, old) {
                (Ok(a), Ok(b)) => {
                    let gap = (a.c - b.c).amax();
                    assert!(gap < 1e-9, "({x}, {y}): {gap:e}");
                    solved += 1;
                    closed += usize::from(igm29(&p, x, y).is_some());
                    steps_new += a.iterations;
                    steps_old += b.iterations;
                }
                (Err(_), Err(_)) => {}
                (a, b) => panic!("({x}, {y}): rod-5 start {a:?}, model-24 start {b:?}"),
            }
        }
    }
    assert!(solved > 500, "only {solved} poses solved");
    assert_eq!(closed, solved, "poses left to the general solver");
    assert!(
        steps_new < steps_old,
        "Newton steps {steps_new} vs {steps_old}"
    );
}

/// The closed-form model-24 igm gives what the general solver gives (Newton from the same
/// start), over the workspace and beyond it, on a machine with parameter errors; and
/// refuses the same poses.
#[test]
fn closed_form_igm24_matches_the_general_solver() {
    let mut p = Params::nominal();
    for (k, i) in [0, 3, 7, 12, 20].into_iter().enumerate() {
        p[i] += 0.05 * (k as f64 + 1.0);
    }
    let mut solved = 0;
    for i in 0..41 {
        for j in 0..41 {
            let (x, y) = (-400.0 + 20.0 * f64::from(i), 300.0 + 70.0 * f64::from(j));
            let fast = igm24(&p, x, y);
            let general = igm_start(&p, x, y)
                .and_then(|c| newton(&p, Model::M24, Subsystem::Tcp, c))
                .and_then(|sol| {
                    for rod in &RODS[..4] {
                        let tcp = Vector2::new(x, y);
                        if !in_assembly_mode(&p, rod, tcp, sol.c[PSI], sol.c[q_var(rod.actuator)]) {
                            return Err(GeometryError::AssemblyMode { rod: rod.number });
                        }
                    }
                    Ok(sol)
                });
            match (fast, general) {
                (Ok(Some(f)), Ok(g)) => {
                    assert_eq!(f.c, g.c, "({x}, {y})");
                    solved += 1;
                }
                (Err(_), Err(_)) => {}
                (f, g) => panic!("({x}, {y}): closed form {f:?}, general {g:?}"),
            }
        }
    }
    assert!(solved > 500, "only {solved} poses solved");
}

/// Parameters with uniform random errors within ±0.1 mm and ±2e-4 rad (the twin's spread).
fn perturbed(seed: u64) -> Params {
    let mut x = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut p = Params::nominal();
    for i in 0..N_PARAMS {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let u = 2.0 * ((x >> 11) as f64 / (1u64 << 53) as f64) - 1.0;
        p[i] += u * match crate::params::unit(i) {
            crate::params::Unit::Mm => 0.1,
            crate::params::Unit::Rad => 2e-4,
        };
    }
    p
}

/// The general forward solver alone: Newton from the model-24 start, then the assembly
/// check of every equation rod (what [`solve`] did before the closed forms).
fn general_fgm(
    p: &Params,
    model: Model,
    sub: Subsystem,
    k: [f64; 2],
) -> Result<Solution, GeometryError> {
    let Subsystem::Actuators(a, b) = sub else {
        unreachable!("forward subsystems only")
    };
    let sol = newton(p, model, sub, fgm_start(p, a, b, k[0], k[1])?)?;
    let t = Trig::new(p, &sol.c);
    match equation_rods(model)
        .iter()
        .find(|r| !rod_in_assembly_mode(p, r, &sol.c, &t))
    {
        Some(rod) => Err(GeometryError::AssemblyMode { rod: rod.number }),
        None => Ok(sol),
    }
}

/// The closed-form forward models ([`fgm_closed`]) of both models and every viable
/// subsystem give what the general solver gives (to 1e-9 mm), close every loop, and
/// return the pose the igm started from (the independent truth of a round trip), over a
/// 25 × 25 grid through the workspace on three machines with random parameter errors; no
/// pose the general solver solves is left to it.
#[test]
fn closed_form_fgm_matches_the_general_solver() {
    for seed in 1..=3 {
        let p = perturbed(seed);
        for model in [Model::M24, Model::M29] {
            for sub in Subsystem::VIABLE {
                let Subsystem::Actuators(a, b) = sub else {
                    unreachable!("forward subsystems only")
                };
                let mut solved = 0;
                for i in 0..25 {
                    for j in 0..25 {
                        let (x, y) = (-300.0 + 25.0 * f64::from(i), 700.0 + 70.0 * f64::from(j));
                        let Ok(pose) = igm(&p, model, x, y) else {
                            continue;
                        };
                        let k = [pose.c[q_var(a)], pose.c[q_var(b)]];
                        let fast = fgm_closed(&p, &frames(&p), model, (a, k[0]), (b, k[1]));
                        match (fast, general_fgm(&p, model, sub, k)) {
                            (Some(f), Ok(g)) => {
                                let gap = (f.c - g.c).amax();
                                assert!(gap < 1e-9, "{model} {sub} ({x}, {y}): {gap:e}");
                                let back = (f.c - pose.c).amax();
                                assert!(
                                    back < 1e-9,
                                    "{model} {sub} ({x}, {y}): round trip {back:e}"
                                );
                                let e = closure(&p, model, &f.c).e.amax();
                                assert!(e < TOL_MM2, "{model} {sub} ({x}, {y}): residual {e:e}");
                                assert_eq!(solve(&p, model, sub, k).unwrap().c, f.c);
                                solved += 1;
                            }
                            (f, g) => {
                                panic!("{model} {sub} ({x}, {y}): closed form {f:?}, general {g:?}")
                            }
                        }
                    }
                }
                assert!(solved > 400, "{model} {sub}: only {solved} poses solved");
            }
        }
    }
}

/// The sensitivities of chosen rows ([`sensitivity_rows_into`], what a calibration row
/// reads) are [`sensitivity_into`]'s rows to the bit, for known and unknown variables of
/// every viable forward subsystem and both models, and leave the other rows untouched;
/// and the full sensitivities predict how the solved configuration moves when a
/// parameter does (central differences of the solver itself, an independent truth).
#[test]
fn chosen_sensitivity_rows_are_the_full_rows_to_the_bit() {
    let p = perturbed(2);
    let mut checked = 0;
    for model in [Model::M24, Model::M29] {
        for sub in Subsystem::VIABLE {
            let Subsystem::Actuators(a, b) = sub else {
                unreachable!("forward subsystems only")
            };
            for (x, y) in [(-200.0, 900.0), (0.0, 1400.0), (150.0, 2000.0)] {
                let Ok(pose) = igm(&p, model, x, y) else {
                    continue;
                };
                let k = [pose.c[q_var(a)], pose.c[q_var(b)]];
                let sol = solve(&p, model, sub, k).expect("fgm of an igm pose");
                let full = sensitivity(&p, model, sub, &sol).expect("regular");
                let vars = [q_var(1), q_var(2), q_var(a)];
                let mut rows = Sensitivity::zeros();
                rows.dc_dp.fill(7.0);
                sensitivity_rows_into(&p, model, (sub, &sol), &frames(&p), &vars, &mut rows)
                    .expect("regular");
                for v in 0..7 {
                    let (want, got) = (full.dc_dp.row(v), rows.dc_dp.row(v));
                    if vars.contains(&v) {
                        let bits = |r: &[f64]| r.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(
                            bits(want.clone_owned().as_slice()),
                            bits(got.clone_owned().as_slice())
                        );
                        assert_eq!(full.dc_dk.row(v), rows.dc_dk.row(v));
                    } else {
                        assert!(got.iter().all(|&e| e == 7.0), "row {v} written");
                    }
                }
                // d q2 / d l1 against the solver's central difference
                let h = 1e-6;
                let (mut up, mut down) = (p, p);
                up[crate::params::L1] += h;
                down[crate::params::L1] -= h;
                let moved = |p: &Params| solve(p, model, sub, k).expect("near").c[q_var(1)];
                let fd = (moved(&up) - moved(&down)) / (2.0 * h);
                let an = full.dc_dp[(q_var(1), crate::params::L1)];
                assert!((fd - an).abs() < 1e-5 * (1.0 + an.abs()), "{fd} vs {an}");
                checked += 1;
            }
        }
    }
    assert!(checked >= 12, "only {checked} poses checked");
}

/// Where the closed form refuses (actuator positions no pose of the machine reaches, or
/// the singular subsystems), [`solve`] answers with the general solver's typed error.
#[test]
fn closed_form_fgm_refusals_keep_the_typed_errors() {
    let p = perturbed(4);
    for model in [Model::M24, Model::M29] {
        let q = igm(&p, model, 0.0, 1700.0).unwrap().q();
        for sub in Subsystem::VIABLE {
            let Subsystem::Actuators(a, b) = sub else {
                unreachable!("forward subsystems only")
            };
            // the two carriers 3 m apart: the rods cannot meet
            let k = [q[a] - 1500.0, q[b] + 1500.0];
            assert!(fgm_closed(&p, &frames(&p), model, (a, k[0]), (b, k[1])).is_none());
            assert_eq!(solve(&p, model, sub, k), general_fgm(&p, model, sub, k));
            assert!(solve(&p, model, sub, k).is_err(), "{model} {sub}");
        }
        // the singular pairs: solved alike where regular, refused alike where not
        for (a, b) in [(1, 3), (0, 2)] {
            let sub = Subsystem::Actuators(a, b);
            for x in [-200.0, 0.0, 200.0] {
                let q = igm(&p, model, x, 1500.0).unwrap().q();
                match (
                    solve(&p, model, sub, [q[a], q[b]]),
                    general_fgm(&p, model, sub, [q[a], q[b]]),
                ) {
                    (Ok(f), Ok(g)) => assert!((f.c - g.c).amax() < 1e-9, "{model} {sub}"),
                    (Err(f), Err(g)) => assert_eq!(
                        std::mem::discriminant(&f),
                        std::mem::discriminant(&g),
                        "{model} {sub}: {f:?} vs {g:?}"
                    ),
                    (f, g) => panic!("{model} {sub}: {f:?} vs {g:?}"),
                }
            }
        }
        let nan = solve(&p, model, Subsystem::NR, [f64::NAN, 1.0]);
        assert_eq!(nan, Err(GeometryError::NonFinite));
    }
}

/// The closed-form conditioning of the forward subsystems ([`fgm_ratio_squared`]) is the
/// general one ([`conditioning_ratio`] on the LU's determinant) to 1e-9 relative, for
/// both models and every pair of drives, the singular pairs (q2, q4) and (q1, q3) near
/// x = 0 included.
#[test]
fn closed_form_fgm_conditioning_is_the_general_ratio() {
    let p = perturbed(5);
    for model in [Model::M24, Model::M29] {
        for (a, b) in [(0, 3), (2, 3), (1, 2), (0, 1), (1, 3), (0, 2)] {
            let sub = Subsystem::Actuators(a, b);
            for (x, y) in [
                (0.0, 1700.0),
                (0.01, 1000.0),
                (-250.0, 900.0),
                (300.0, 2200.0),
            ] {
                let sol = igm(&p, model, x, y).unwrap();
                let cl = closure(&p, model, &sol.c);
                let e_u = select_columns(&cl.e_c, &sub.unknown());
                let general = conditioning_ratio(&e_u, Lu5::new(e_u).map(|l| l.det));
                let rows = std::array::from_fn(|i| {
                    let j = q_var(RODS[i].actuator);
                    [
                        cl.e_c[(i, X)],
                        cl.e_c[(i, Y)],
                        cl.e_c[(i, PSI)],
                        cl.e_c[(i, j)],
                    ]
                });
                let closed = fgm_ratio_squared(model, a, b, &rows).sqrt();
                assert!(
                    (closed - general).abs() <= 1e-9 * general.max(1e-6),
                    "{model} {sub} ({x}, {y}): {closed:e} vs {general:e}"
                );
            }
        }
    }
}

#[test]
fn spec_check_values() {
    let p = Params::nominal();
    for model in [Model::M24, Model::M29] {
        let s = igm(&p, model, 0.0, 1700.0).expect("igm");
        let q = s.q();
        let want = [2611.0556, 2611.0556, 788.9444, 788.9444];
        for i in 0..4 {
            assert!(
                (q[i] - want[i]).abs() < 1e-4,
                "{model} q{} = {}",
                i + 1,
                q[i]
            );
        }
        assert!(s.psi().abs() < 1e-12);
    }
}

/// The model-29 forward model with its secant warm-started from the previous sample's ψ
/// ([`fgm29_from`], the elastic checks' rigid reference) is the pose of the one from γ2
/// (to 1e-9 mm and rad), over a servo-like trajectory (a 100 mm circle in 2,000 samples,
/// and a 600 mm diagonal in 10 jumps, both carried from sample to sample) on three
/// machines with random parameter errors, for every viable subsystem; a wild warm ψ
/// (0.5 rad off) falls back to the same pose too.
#[test]
fn warm_rigid_psi_gives_the_pose_from_gamma2() {
    let circle = (0..2000).map(|i| {
        let t = f64::from(i) / 2000.0 * std::f64::consts::TAU;
        (100.0 * t.cos(), 1700.0 + 100.0 * t.sin())
    });
    let diagonal = (0..10).map(|i| (-300.0 + 60.0 * f64::from(i), 900.0 + 80.0 * f64::from(i)));
    let path: Vec<(f64, f64)> = circle.chain(diagonal).collect();
    for seed in 1..=3 {
        let p = perturbed(seed);
        let fr = frames(&p);
        for sub in Subsystem::VIABLE {
            let Subsystem::Actuators(a, b) = sub else {
                unreachable!("forward subsystems only")
            };
            let mut warm: Option<f64> = None;
            for &(x, y) in &path {
                let q = igm(&p, Model::M29, x, y).expect("igm").q();
                let known = [q[a], q[b]];
                let cold = fgm_with_frames(&p, &fr, Model::M29, sub, known).expect("fgm");
                // the warm secant itself settles where the closed form from γ2 does
                if let Some(w) = warm {
                    let ks = ((a, known[0]), (b, known[1]));
                    let closed = fgm_closed(&p, &fr, Model::M29, ks.0, ks.1).is_some();
                    let settled = settled_psi_fgm(&p, &fr, ks, Some(w))
                        .is_some_and(|(psi, _)| (psi - w).abs() <= WARM_PSI_RAD);
                    assert!(settled || !closed, "seed {seed} {sub} ({x}, {y})");
                }
                for start in [warm.unwrap_or(p[GAMMA2]), cold.c[PSI] + 0.5] {
                    let hot = fgm29_from(&p, &fr, (a, b), known, start).expect("warm fgm");
                    let gap = (hot.c - cold.c).amax();
                    assert!(gap < 1e-9, "seed {seed} {sub} ({x}, {y}): {gap:e}");
                }
                warm = Some(cold.c[PSI]);
            }
        }
    }
}

/// The slope of rod 5's closure that the warm Newton step takes ([`rod5_open_slope`]) is
/// the closure's derivative in ψ: against central differences (h = 1e-6 rad, whose error
/// h²·g‴/6 and round-off are below 1e-7 of the slope's 6e5 mm²/rad), for every viable
/// subsystem (q4 known and from rod 4), at the settled ψ and 1 mrad either side, on three
/// machines with parameter errors.
#[test]
fn rod5_slope_is_the_closure_derivative() {
    let h = 1e-6;
    let mut compared = 0;
    for seed in 1..=3 {
        let p = perturbed(seed);
        let fr = frames(&p);
        for (x, y) in [(0.0, 1700.0), (-250.0, 1000.0), (300.0, 2300.0)] {
            let c = igm(&p, Model::M29, x, y).expect("igm").c;
            for sub in Subsystem::VIABLE {
                let Subsystem::Actuators(a, b) = sub else {
                    unreachable!("forward subsystems only")
                };
                let (ka, kb) = ((a, c[q_var(a)]), (b, c[q_var(b)]));
                for psi in [c[PSI] - 1e-3, c[PSI], c[PSI] + 1e-3] {
                    let g = |v: f64| rod5_open(&p, &fr, ka, kb, v.sin_cos()).expect("open");
                    let (g0, slope) =
                        rod5_open_slope(&p, &fr, ka, kb, psi.sin_cos()).expect("slope");
                    let numeric = (g(psi + h) - g(psi - h)) / (2.0 * h);
                    assert!((g0 - g(psi)).abs() <= 1e-9 * g0.abs().max(1.0));
                    let gap = (slope - numeric).abs();
                    assert!(
                        gap <= 1e-7 * slope.abs(),
                        "seed {seed} {sub} ({x}, {y}) ψ {psi}: {slope:e} vs {numeric:e}"
                    );
                    compared += 1;
                }
            }
        }
    }
    assert_eq!(compared, 108);
}

#[test]
fn q2_q4_subsystem_is_singular_at_x0() {
    let p = Params::nominal();
    let s = igm(&p, Model::M24, 0.0, 1700.0).expect("igm");
    let q = s.q();
    let r = solve(&p, Model::M24, Subsystem::Actuators(1, 3), [q[1], q[3]]);
    assert!(
        matches!(
            r,
            Err(GeometryError::Singular { .. } | GeometryError::NoIntersection { .. })
        ),
        "{r:?}"
    );
}
