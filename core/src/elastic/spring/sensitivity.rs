//! The platform's balance and the equilibrium's sensitivities to the parameters.

use super::energy::{dr_dz, drho_dz, rod_state, rod_state_with, system, M7, V7};
use super::equilibrium::{ElasticError, Equilibrium, Followers, Stiffness};
use crate::geometry::{frames, Frames};
use crate::params::{Params, N_PARAMS, RODS};
use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

/// Force and moment balance of the platform at an equilibrium: (Σ F_x, Σ F_y, Σ M_z about the
/// TCP), N and N·mm, from the rod forces alone (no external load).
pub fn platform_balance(p: &Params, eq: &Equilibrium) -> [f64; 3] {
    lengths_and_balance(p, &frames(p), eq).1
}

/// The rods' lengths |A − B| at an equilibrium's pose and carriers, and the platform's
/// balance ([`platform_balance`]), in one pass with the trigonometry once (three sin_cos for
/// the five rods): what the plausibility checks read.
pub(crate) fn lengths_and_balance(
    p: &Params,
    fr: &Frames,
    eq: &Equilibrium,
) -> ([f64; 5], [f64; 3]) {
    let z = eq.z();
    let sc = z[2].sin_cos();
    let mut lengths = [0.0; 5];
    let mut out = [0.0; 3];
    for (i, rho) in lengths.iter_mut().enumerate() {
        let st = rod_state_with(p, fr, sc, i, &z);
        *rho = st.rho;
        // A rod in tension pulls the platform joint towards its carrier: force −T·u.
        let f = -st.u * eq.rod_force[i];
        out[0] += f.x;
        out[1] += f.y;
        out[2] += st.arm.x * f.y - st.arm.y * f.x;
    }
    (lengths, out)
}

/// Sensitivities of an equilibrium (implicit-function theorem on ∇V = 0).
#[derive(Clone, Copy, Debug)]
pub struct ElasticSensitivity {
    /// ∂(x, y, ψ)/∂(q1..q4).
    pub dpose_dq: SMatrix<f64, 3, 4>,
    /// ∂(x, y, ψ)/∂p (29 parameters).
    pub dpose_dp: SMatrix<f64, 3, N_PARAMS>,
    /// ∂(s1..s4)/∂(q1..q4): how followers' carriers move.
    pub dcarrier_dq: SMatrix<f64, 4, 4>,
}

/// One parameter's share in a rod's terms: (parameter index, ∂r/∂p, ∂J/∂p as (column,
/// vector) or none, ∂l/∂p).
type RodPartial = (usize, Vector2<f64>, Option<(usize, Vector2<f64>)>, f64);

/// ∂G/∂p of the equilibrium at `z`: the rod terms, only in the rows that are not replaced by
/// rigid constraints.
fn g_params(
    p: &Params,
    k: &Stiffness,
    followers: Followers,
    z: &SVector<f64, 7>,
) -> SMatrix<f64, 7, N_PARAMS> {
    let mut g_p = SMatrix::<f64, 7, N_PARAMS>::zeros();
    let (sn, cs) = z[2].sin_cos();
    for (i, rod) in RODS.iter().enumerate() {
        let st = rod_state(p, i, z);
        let ki = k.rod[i];
        let t = ki * st.delta;
        let d = drho_dz(&st);
        let j = dr_dz(&st);
        let proj = Matrix2::identity() - st.u * st.u.transpose();
        let s = z[3 + rod.actuator];
        let along = s + p[rod.yb];
        // (parameter index, ∂r/∂p, ∂J/∂p as (column, vector) or none, ∂l/∂p)
        let dr: [RodPartial; 7] = [
            (rod.l, Vector2::zeros(), None, 1.0),
            (
                rod.xa,
                Vector2::new(cs, sn),
                Some((2, Vector2::new(-sn, cs))),
                0.0,
            ),
            (
                rod.ya,
                Vector2::new(-sn, cs),
                Some((2, Vector2::new(-cs, -sn))),
                0.0,
            ),
            (rod.xb, -st.n, None, 0.0),
            (rod.yb, -st.e, None, 0.0),
            (rod.guide.d_index(), Vector2::new(-1.0, 0.0), None, 0.0),
            (
                rod.guide.gamma_index(),
                -(st.e * p[rod.xb] - st.n * along),
                Some((3 + rod.actuator, st.n)),
                0.0,
            ),
        ];
        for (pi, drp, djp, dl) in dr {
            let ddelta = st.u.dot(&drp) - dl;
            let mut col = d * (ki * ddelta);
            col += j.transpose() * (proj * drp) * (t / st.rho);
            if let Some((c, v)) = djp {
                col[c] += t * st.u.dot(&v);
            }
            for row in 0..7 {
                g_p[(row, pi)] += col[row];
            }
        }
    }
    for j in 0..4 {
        if !followers[j] && k.carrier[j].is_none() {
            for c in 0..N_PARAMS {
                g_p[(3 + j, c)] = 0.0;
            }
        }
    }
    g_p
}

/// Analytic sensitivities of `eq` (solved for `q`, `followers`).
pub fn sensitivity(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    eq: &Equilibrium,
) -> Result<ElasticSensitivity, ElasticError> {
    let z = eq.z();
    let (mut g, mut h) = (V7::zeros(), M7::zeros());
    system(
        p,
        &frames(p),
        k,
        (&q, followers),
        (&z, z[2].sin_cos()),
        false,
        (&mut g, &mut h),
    );
    let lu = h.lu();
    // ∂G/∂q: only the rows of active carriers depend on q.
    let mut g_q = SMatrix::<f64, 7, 4>::zeros();
    for j in 0..4 {
        if !followers[j] {
            g_q[(3 + j, j)] = match k.carrier[j] {
                Some(c) => -c,
                None => -1.0,
            };
        }
    }
    let g_p = g_params(p, k, followers, &z);
    let dz_dq = lu
        .solve(&g_q)
        .ok_or(ElasticError::Singular { iteration: 0 })?;
    let dz_dp = lu
        .solve(&g_p)
        .ok_or(ElasticError::Singular { iteration: 0 })?;
    Ok(ElasticSensitivity {
        dpose_dq: -dz_dq.fixed_rows::<3>(0).into_owned(),
        dpose_dp: -dz_dp.fixed_rows::<3>(0).into_owned(),
        dcarrier_dq: -dz_dq.fixed_rows::<4>(3).into_owned(),
    })
}
