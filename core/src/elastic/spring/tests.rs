//! Unit tests of `spring`.

use super::energy::{dr_dz, drho_dz, rod_state_with, system, M7, V7};
use super::solve::spd_step;
use super::*;
use crate::elastic::fegm;
use crate::geometry::{self, frames, Frames};
use crate::params::{Model, Params};
use nalgebra::Matrix2;

/// The dense rod terms the solver assembled before [`rod_terms`]: k·d·dᵀ + (T/ρ)·JᵀPJ.
fn dense_rod_terms(p: &Params, fr: &Frames, k: &Stiffness, z: &V7) -> (V7, M7) {
    let (mut g, mut h) = (V7::zeros(), M7::zeros());
    for i in 0..5 {
        let st = rod_state_with(p, fr, z[2].sin_cos(), i, z);
        let t = k.rod[i] * st.delta;
        let d = drho_dz(&st);
        g += d * t;
        let j = dr_dz(&st);
        let proj = Matrix2::identity() - st.u * st.u.transpose();
        h += d * d.transpose() * k.rod[i];
        h += j.transpose() * proj * j * (t / st.rho);
        h[(2, 2)] += t * (-st.u.dot(&st.arm));
    }
    (g, h)
}

/// The sparse assembly ([`rod_terms`]) is the dense one, and the Cholesky on the free
/// unknowns ([`spd_step`]) gives nalgebra's Cholesky step on the whole matrix, to round-off:
/// at equilibria and off them, rigid and compliant carriers, all drives active and q2, q3
/// followers. So the warm fegm's iterates, and its result, are those of before.
#[test]
fn sparse_assembly_and_free_cholesky_match_the_dense_forms() {
    let mut p = Params::nominal();
    for (n, i) in [0, 3, 7, 12, 20, 24, 26].into_iter().enumerate() {
        p[i] += 0.03 * (n as f64 + 1.0);
    }
    let fr = frames(&p);
    let compliant = Stiffness {
        carrier: [Some(4e4), None, Some(6e4), Some(5e4)],
        ..Stiffness::default()
    };
    let mut steps = 0;
    for k in [Stiffness::default(), compliant] {
        for (x, y) in [(0.0, 1700.0), (-200.0, 1100.0), (250.0, 2300.0)] {
            let q = geometry::igm(&p, Model::M29, x, y).unwrap().q();
            let q = [q[0], q[1], q[2] + 0.2, q[3]];
            for fol in [ALL_ACTIVE, FOLLOWERS_23] {
                let eq = fegm(&p, &k, q, fol).unwrap();
                for dz in [0.0, 0.3] {
                    let z = eq.z() + V7::from([dz, -dz, 1e-3 * dz, 0.0, dz, -dz, 0.0]);
                    let (g0, h0) = dense_rod_terms(&p, &fr, &k, &z);
                    let (mut g1, mut h1) = (V7::zeros(), M7::zeros());
                    assert!(system(
                        &p,
                        &fr,
                        &k,
                        (&q, [true; 4]),
                        (&z, z[2].sin_cos()),
                        true,
                        (&mut g1, &mut h1)
                    ));
                    assert!(
                        (g1 - g0).amax() <= 1e-9 * g0.amax().max(1.0),
                        "{g1} vs {g0}"
                    );
                    assert!((h1 - h0).amax() <= 1e-9 * h0.amax(), "{h1} vs {h0}");
                    let mut zq = z;
                    for j in (0..4).filter(|&j| !fol[j] && k.carrier[j].is_none()) {
                        zq[3 + j] = q[j];
                    }
                    let (mut g, mut h) = (V7::zeros(), M7::zeros());
                    system(
                        &p,
                        &fr,
                        &k,
                        (&q, fol),
                        (&zq, zq[2].sin_cos()),
                        true,
                        (&mut g, &mut h),
                    );
                    // the symmetric system: the dense terms with the rigid drives' rows
                    // and columns replaced by their constraints
                    let (mut gd, mut hd) = dense_rod_terms(&p, &fr, &k, &zq);
                    for j in (0..4).filter(|&j| !fol[j]) {
                        let v = 3 + j;
                        if let Some(c) = k.carrier[j] {
                            gd[v] += c * (zq[v] - q[j]);
                            hd[(v, v)] += c;
                        } else {
                            gd[v] = zq[v] - q[j];
                            hd.row_mut(v).fill(0.0);
                            hd.column_mut(v).fill(0.0);
                            hd[(v, v)] = 1.0;
                        }
                    }
                    assert!((g - gd).amax() <= 1e-9 * gd.amax().max(1.0), "{g} vs {gd}");
                    assert!((h - hd).amax() <= 1e-9 * hd.amax(), "{h} vs {hd}");
                    let free: Vec<usize> = (0..7)
                        .filter(|&v| v < 3 || fol[v - 3] || k.carrier[v - 3].is_some())
                        .collect();
                    let ours = spd_step(&h, &g, &free).unwrap();
                    let want = h.cholesky().unwrap().solve(&g);
                    assert!((ours - want).amax() <= 1e-9 * want.amax().max(1e-9));
                    steps += 1;
                }
            }
        }
    }
    assert_eq!(steps, 24);
    // not positive definite on the free unknowns: None, the caller's LU decides
    let h = -M7::identity();
    assert!(spd_step(&h, &V7::repeat(1.0), &[0, 1, 2]).is_none());
}
