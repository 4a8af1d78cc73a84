//! The equilibrium's Newton: its rigid or warm start, the step through the free unknowns, the
//! result checked.

use super::energy::{rod_state_with, system, M7, V7};
use super::equilibrium::{converged, ElasticError, Equilibrium, Followers, Stiffness, MAX_ITER};
use crate::elastic::limits::wrap_angle;
use crate::geometry::{self, frames, near, Frames, Subsystem};
use crate::params::{Model, Params};

/// Rigid start: the model-29 forward model of the first viable subsystem whose two drives are
/// active, at the commanded positions; its secant in ψ from `psi_warm` where given (the
/// previous sample's rigid ψ, never the elastic one: the same pose, in fewer closures).
pub(crate) fn rigid_start(
    p: &Params,
    fr: &Frames,
    (q, fol): (&[f64; 4], Followers),
    psi_warm: Option<f64>,
) -> Result<V7, ElasticError> {
    for sub in Subsystem::VIABLE {
        if let Subsystem::Actuators(a, b) = sub {
            if fol[a] || fol[b] {
                continue;
            }
            let known = [q[a], q[b]];
            let s = match psi_warm {
                Some(w) => geometry::fgm29_from(p, fr, (a, b), known, w)?,
                None => geometry::fgm_with_frames(p, fr, Model::M29, sub, known)?,
            };
            let c = s.c;
            return Ok(V7::from([c[0], c[1], c[2], c[3], c[4], c[5], c[6]]));
        }
    }
    Err(ElasticError::NotHeld)
}

/// The raw solver without any plausibility check, from `previous` or else from the rigid
/// start: for studies of the solver and for tests of the checks. Its result may be a
/// non-physical branch; everything else goes through [`fegm_checked`].
pub fn fegm_unchecked(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    previous: Option<&Equilibrium>,
) -> Result<Equilibrium, ElasticError> {
    if !q.iter().all(|v| v.is_finite()) {
        return Err(ElasticError::NonFinite);
    }
    let fr = frames(p);
    let z0 = match previous {
        Some(prev) => warm_start(&q, followers, prev),
        None => rigid_start(p, &fr, (&q, followers), None)?,
    };
    solve_from(p, &fr, k, q, followers, z0).map(|sol| sol.eq)
}

/// The previous equilibrium with the active carriers moved to their new commands.
pub(crate) fn warm_start(q: &[f64; 4], followers: Followers, previous: &Equilibrium) -> V7 {
    let mut z0 = previous.z();
    for j in 0..4 {
        if !followers[j] {
            z0[3 + j] = q[j];
        }
    }
    z0
}

/// An equilibrium with its rods' lengths and the platform's balance, from the pass over the
/// rods that computes its forces ([`finish`]): what the plausibility checks read, which
/// [`lengths_and_balance`] would compute again from the equilibrium's fields, the same rods
/// at the same state.
pub(crate) struct Solved {
    pub(crate) eq: Equilibrium,
    pub(crate) lengths: [f64; 5],
    pub(crate) balance: [f64; 3],
}

pub(crate) fn solve_from(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    z: V7,
) -> Result<Solved, ElasticError> {
    newton(p, fr, k, (q, followers), z, converged)
}

/// Newton on the equilibrium from z, stopping where `stop(step, previous step)` says.
fn newton(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    (q, followers): ([f64; 4], Followers),
    mut z: V7,
    stop: impl Fn(f64, f64) -> bool,
) -> Result<Solved, ElasticError> {
    for j in 0..4 {
        if !followers[j] && k.carrier[j].is_none() {
            z[3 + j] = q[j];
        }
    }
    let mut last_step = f64::INFINITY;
    let mut gnorm = f64::INFINITY;
    // ψ's sine and cosine once, rotated for the iterates (`near`, sin_cos again beyond 1 mrad
    // from the start): three sin_cos per solve were a tenth of the checked warm fegm
    let anchor = (z[2], z[2].sin_cos());
    // the system's buffers, filled in place by every iteration
    let (mut g, mut h) = (V7::zeros(), M7::zeros());
    // the unknowns Newton moves: pose, followers' and compliant carriers
    let mut free = [0; 7];
    let mut n_free = 0;
    for (slot, v) in free
        .iter_mut()
        .zip((0..7).filter(|&v| v < 3 || followers[v - 3] || k.carrier[v - 3].is_some()))
    {
        *slot = v;
        n_free += 1;
    }
    for it in 0..MAX_ITER {
        let sc = near(anchor, z[2]);
        if !system(p, fr, k, (&q, followers), (&z, sc), true, (&mut g, &mut h)) {
            return Err(ElasticError::Degenerate);
        }
        gnorm = g.amax();
        if !gnorm.is_finite() {
            return Err(ElasticError::NonFinite);
        }
        // The tangent stiffness is symmetric and, near a stable equilibrium, positive definite:
        // Cholesky on the free unknowns, with LU of the whole matrix as the fallback.
        let step = match spd_step(&h, &g, &free[..n_free]) {
            Some(step) => step,
            _ => h
                .lu()
                .solve(&g)
                .ok_or(ElasticError::Singular { iteration: it })?,
        };
        z -= step;
        let previous = last_step;
        last_step = step.amax();
        if !last_step.is_finite() {
            return Err(ElasticError::NonFinite);
        }
        if stop(last_step, previous) {
            return Ok(finish(
                p,
                fr,
                k,
                followers,
                (&z, near(anchor, z[2])),
                it + 1,
            ));
        }
    }
    Err(ElasticError::NotConverged {
        iterations: MAX_ITER,
        step: last_step,
        gradient: gnorm,
    })
}

/// The Newton step H⁻¹g of the symmetric system, whose rows and columns of rigid active
/// carriers are unit ones (with g = 0 there once the carriers sit at their commands): a
/// Cholesky (LDLᵀ) on the `free` unknowns only, on the stack (3 of 7 unknowns when every
/// drive holds a rigid carrier, the servo-rate case, where the whole 7 × 7 factorisation cost
/// more than the rest of the iteration). None where H is not positive definite on them: the
/// caller then takes the LU of the whole matrix, as before.
pub(super) fn spd_step(h: &M7, g: &V7, free: &[usize]) -> Option<V7> {
    // the pose is always free: 3 to 7 unknowns, each count its own factorisation with the
    // size known at compile time (unrolled, no bounds checks: with the count a run-time
    // value, the loops over 3 unknowns cost as much as the rest of a Newton iteration)
    match free.len() {
        3 => ldl_step::<3>(h, g, free),
        4 => ldl_step::<4>(h, g, free),
        5 => ldl_step::<5>(h, g, free),
        6 => ldl_step::<6>(h, g, free),
        7 => ldl_step::<7>(h, g, free),
        _ => None,
    }
}

/// [`spd_step`] on N free unknowns.
#[inline]
fn ldl_step<const N: usize>(h: &M7, g: &V7, free: &[usize]) -> Option<V7> {
    let free: &[usize; N] = free.try_into().ok()?;
    // the free block, gathered once
    let mut a = [[0.0f64; N]; N];
    for (row, &r) in a.iter_mut().zip(free) {
        for (v, &c) in row.iter_mut().zip(free) {
            *v = h[(r, c)];
        }
    }
    // LDLᵀ, the Cholesky without its roots: H positive definite on the free unknowns exactly
    // when every pivot d is; the pivots' reciprocals once, so that the factorisation and
    // both solves multiply (the divisions and roots in a chain were most of the step)
    let mut l = [[0.0f64; N]; N];
    let (mut d, mut inv_d) = ([0.0f64; N], [0.0f64; N]);
    for i in 0..N {
        for j in 0..i {
            let dot: f64 = (0..j).map(|k| l[i][k] * l[j][k] * d[k]).sum();
            l[i][j] = (a[i][j] - dot) * inv_d[j];
        }
        let di = a[i][i] - (0..i).map(|k| l[i][k] * l[i][k] * d[k]).sum::<f64>();
        if !(di > 0.0) {
            return None;
        }
        (d[i], inv_d[i]) = (di, 1.0 / di);
    }
    let mut y = [0.0f64; N];
    for i in 0..N {
        let dot: f64 = l[i][..i].iter().zip(&y[..i]).map(|(a, b)| a * b).sum();
        y[i] = g[free[i]] - dot;
    }
    for i in (0..N).rev() {
        let mut s = y[i] * inv_d[i];
        for k in i + 1..N {
            s -= l[k][i] * y[k];
        }
        y[i] = s;
    }
    // the fixed unknowns' rows are unit rows: their step is g there
    let mut step = *g;
    for (&v, &yi) in free.iter().zip(&y) {
        step[v] = yi;
    }
    Some(step)
}

/// The equilibrium at z (`sc`: sin and cos of ψ = z[2]) with its forces, the rods' lengths
/// and the platform's balance, in one pass over the rods.
fn finish(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    fol: Followers,
    (z, sc): (&V7, (f64, f64)),
    iterations: usize,
) -> Solved {
    let mut rod_force = [0.0; 5];
    let mut drive_force = [0.0; 4];
    let (mut lengths, mut balance) = ([0.0; 5], [0.0; 3]);
    for (i, f) in rod_force.iter_mut().enumerate() {
        let st = rod_state_with(p, fr, sc, i, z);
        *f = k.rod[i] * st.delta;
        // Force of the drive on its carrier balances the rod's pull T·u along the guide.
        drive_force[st.carrier] -= *f * st.u.dot(&st.e);
        // as lengths_and_balance: the length, and the rod's force −T·u on the platform
        lengths[i] = st.rho;
        let on_platform = -st.u * *f;
        balance[0] += on_platform.x;
        balance[1] += on_platform.y;
        balance[2] += st.arm.x * on_platform.y - st.arm.y * on_platform.x;
    }
    for j in 0..4 {
        if fol[j] {
            drive_force[j] = 0.0;
        }
    }
    let eq = Equilibrium {
        x: z[0],
        y: z[1],
        // The solver works on sin/cos of ψ only: a warm start may drift by whole turns.
        psi: wrap_angle(z[2]),
        carrier: [z[3], z[4], z[5], z[6]],
        rod_force,
        drive_force,
        iterations,
    };
    Solved {
        eq,
        lengths,
        balance,
    }
}
