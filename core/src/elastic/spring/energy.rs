//! The potential energy's gradient and Hessian (tangent stiffness, geometric terms included) at
//! a state z.

use super::equilibrium::{Followers, Stiffness};
use crate::geometry::{frames, Frames};
use crate::params::{Guide, Params, RODS};
use nalgebra::{SMatrix, SVector, Vector2};

pub(super) type V7 = SVector<f64, 7>;
pub(super) type M7 = SMatrix<f64, 7, 7>;

/// Per-rod kinematic quantities at a state z.
pub(super) struct RodState {
    /// Carrier index 0..=3 (unknown index 3 + carrier).
    pub(super) carrier: usize,
    pub(super) rho: f64,
    pub(super) u: Vector2<f64>,
    pub(super) delta: f64,
    /// A − P (platform joint relative to the TCP, rotated): ∂r/∂ψ = perp(A − P).
    pub(super) arm: Vector2<f64>,
    pub(super) e: Vector2<f64>,
    pub(super) n: Vector2<f64>,
}

pub(super) fn rod_state(p: &Params, i: usize, z: &V7) -> RodState {
    rod_state_with(p, &frames(p), z[2].sin_cos(), i, z)
}

#[inline]
pub(super) fn rod_state_with(
    p: &Params,
    fr: &Frames,
    sc: (f64, f64),
    i: usize,
    z: &V7,
) -> RodState {
    let rod = &RODS[i];
    let (sn, cs) = sc;
    let (xa, ya) = (p[rod.xa], p[rod.ya]);
    let arm = Vector2::new(cs * xa - sn * ya, sn * xa + cs * ya);
    let a = Vector2::new(z[0], z[1]) + arm;
    let (o, e, n) = match rod.guide {
        Guide::G1 => fr[0],
        Guide::G2 => fr[1],
    };
    let s = z[3 + rod.actuator];
    let b = o + n * p[rod.xb] + e * (s + p[rod.yb]);
    let r = a - b;
    let rho = r.norm();
    let u = r / rho;
    RodState {
        carrier: rod.actuator,
        rho,
        u,
        delta: rho - p[rod.l],
        arm,
        e,
        n,
    }
}

/// Column vector Jᵀu for the rod: ∂ρ/∂z.
#[inline]
pub(super) fn drho_dz(st: &RodState) -> V7 {
    let mut g = V7::zeros();
    g[0] = st.u.x;
    g[1] = st.u.y;
    // ∂r/∂ψ = R'(ψ)a = perp(arm) = (−arm.y, arm.x)
    g[2] = st.u.x * (-st.arm.y) + st.u.y * st.arm.x;
    g[3 + st.carrier] = -st.u.dot(&st.e);
    g
}

/// ∂r/∂z as a 2×7 matrix.
#[inline]
pub(super) fn dr_dz(st: &RodState) -> SMatrix<f64, 2, 7> {
    let mut j = SMatrix::<f64, 2, 7>::zeros();
    j[(0, 0)] = 1.0;
    j[(1, 1)] = 1.0;
    j[(0, 2)] = -st.arm.y;
    j[(1, 2)] = st.arm.x;
    j[(0, 3 + st.carrier)] = -st.e.x;
    j[(1, 3 + st.carrier)] = -st.e.y;
    j
}

/// One rod's share of the gradient and the tangent stiffness. A rod's terms touch four
/// unknowns only (x, y, ψ, its carrier), so they are assembled on those: with d = ∂ρ/∂z = Jᵀu
/// and J = ∂r/∂z, k·d·dᵀ + (T/ρ)·Jᵀ(I − u·uᵀ)J = (k − T/ρ)·d·dᵀ + (T/ρ)·JᵀJ, a 4 × 4 block of
/// dot products instead of the dense 7 × 7 products (which cost most of a warm solve).
/// `M` = 4 assembles all four; `M` = 3 the pose's only, for a carrier whose row and column
/// the symmetric system replaces by its drive's constraint (see [`system`]): 6 entries of 10.
#[inline]
fn rod_terms<const M: usize>(st: &RodState, ki: f64, g: &mut V7, h: &mut M7) {
    let t = ki * st.delta;
    let idx = [0, 1, 2, 3 + st.carrier];
    // columns of J: ∂r/∂x, ∂r/∂y, ∂r/∂ψ = perp(arm), ∂r/∂s = −e
    let jc = [
        Vector2::new(1.0, 0.0),
        Vector2::new(0.0, 1.0),
        Vector2::new(-st.arm.y, st.arm.x),
        -st.e,
    ];
    let d = jc.map(|c| st.u.dot(&c));
    let (tr, kk) = (t / st.rho, ki - t / st.rho);
    for a in 0..M {
        g[idx[a]] += d[a] * t;
        for b in a..M {
            let v = kk * d[a] * d[b] + tr * jc[a].dot(&jc[b]);
            h[(idx[a], idx[b])] += v;
            if a != b {
                h[(idx[b], idx[a])] += v;
            }
        }
    }
    // ∂²r/∂ψ² = −arm
    h[(2, 2)] -= t * st.u.dot(&st.arm);
}

/// Gradient (generalised forces) and Hessian (tangent stiffness) of the system, with the rows of
/// rigid active carriers replaced by s_j − q_j = 0. With `symmetric`, their columns are zeroed
/// too, which keeps the matrix symmetric for the Newton step (valid because the solver keeps
/// s_j = q_j exactly, so those components of the step are 0); the sensitivities need the
/// unsymmetric form. Inlined: its 7 × 7 result was copied out on every Newton iteration.
/// `sc`: sin and cos of ψ = z[2].
#[inline]
pub(super) fn system(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    (q, fol): (&[f64; 4], Followers),
    (z, sc): (&V7, (f64, f64)),
    symmetric: bool,
    (g, h): (&mut V7, &mut M7),
) -> bool {
    // whole assignments: nalgebra's fill walked the 49 entries one by one with index
    // arithmetic, a fifth of this function
    *g = V7::zeros();
    *h = M7::zeros();
    let mut ok = true;
    // drives whose row (and, symmetric, column) the constraint s_j − q_j = 0 replaces
    let fixed = |j: usize| !fol[j] && k.carrier[j].is_none();
    for i in 0..5 {
        let st = rod_state_with(p, fr, sc, i, z);
        if !(st.rho > 1e-9) {
            ok = false;
            continue;
        }
        if symmetric && fixed(st.carrier) {
            rod_terms::<3>(&st, k.rod[i], g, h);
        } else {
            rod_terms::<4>(&st, k.rod[i], g, h);
        }
    }
    for j in 0..4 {
        if fol[j] {
            continue;
        }
        let v = 3 + j;
        if let Some(c) = k.carrier[j] {
            g[v] += c * (z[v] - q[j]);
            h[(v, v)] += c;
        } else {
            g[v] = z[v] - q[j];
            // symmetric, the rods left this row and column out (rod_terms::<3>); else the
            // row is the constraint's and the columns keep the rods' terms
            if !symmetric {
                for col in 0..7 {
                    h[(v, col)] = 0.0;
                }
            }
            h[(v, v)] = 1.0;
        }
    }
    ok
}
