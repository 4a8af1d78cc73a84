//! Physical plausibility of an elastic equilibrium.
//!
//! Newton on ∇V = 0 finds stationary points of the potential energy, not only the stable
//! equilibrium of the machine: warm-started after a large jump of the actuators (1 m between
//! two setups of a campaign), it can land on a branch where the platform is turned over
//! (ψ ≈ π), the rods stretched by a metre and the drives pushing 10⁸ N, and report it as
//! converged. Such a state balances its own equations, so convergence alone says nothing; the
//! checks here compare it with what the machine can be:
//!
//! - [`Reason::LoopClosure`]: every rod's length agrees with its force (|A_i − B_i| = l_i +
//!   F_i/k_i), every active carrier sits where its drive holds it, every follower's carrier
//!   near the position its encoder reads;
//! - [`Reason::ForceBalance`]: the platform is in force and moment balance;
//! - [`Reason::ForceLimit`]: no rod or drive force far beyond what the drives can give
//!   (a multiple of the nominal 8,600 N);
//! - [`Reason::PlatformAngle`]: ψ near γ2 (the parallel-holder keeps it there);
//! - [`Reason::FarFromRigid`]: the TCP near the rigid forward model of the holding drives,
//!   which also places it inside the reachable workspace and in the assembly mode;
//! - [`Reason::NotConverged`]: a non-finite state, or no elastic solution at all.
//!
//! Nothing here allocates: the checks run on every servo sample.

use super::limits::{wrap_angle, Limits, Reason, RigidPose, Violation};
use super::spring::{
    lengths_and_balance, Equilibrium, Followers, Stiffness, NOMINAL_DRIVE_FORCE_N,
};
use crate::geometry::frames;
use crate::params::{Params, GAMMA2};

/// `value` within `limit`; false for NaN, so a non-finite value always fails its check.
fn within(value: f64, limit: f64) -> bool {
    value <= limit
}

fn fail(reason: Reason, item: usize, value: f64, limit: f64) -> Result<(), Violation> {
    Err(Violation {
        reason,
        item: u8::try_from(item).unwrap_or(u8::MAX),
        value,
        limit,
    })
}

/// Checks `eq`, solved for encoder readings `q` (mm) with `followers`, against physics and
/// the `rigid` forward model of the same readings. The first failed check is returned,
/// cheapest first.
pub fn check(
    p: &Params,
    k: &Stiffness,
    q: &[f64; 4],
    followers: &Followers,
    eq: &Equilibrium,
    rigid: &RigidPose,
    limits: &Limits,
) -> Result<(), Violation> {
    let (lengths, balance) = lengths_and_balance(p, &frames(p), eq);
    check_with(
        p,
        k,
        (q, *followers),
        eq,
        (&lengths, balance),
        rigid,
        limits,
    )
}

/// [`check`] with the rods' lengths |A − B| and the platform's balance at `eq` given (the
/// guarded solve has them from the pass over the rods that computed `eq`'s forces, at the
/// same state).
pub(super) fn check_with(
    p: &Params,
    k: &Stiffness,
    (q, followers): (&[f64; 4], Followers),
    eq: &Equilibrium,
    (lengths, balance): (&[f64; 5], [f64; 3]),
    rigid: &RigidPose,
    limits: &Limits,
) -> Result<(), Violation> {
    let pose_finite = [eq.x, eq.y, eq.psi].iter().all(|v| v.is_finite());
    let forces_finite = eq
        .rod_force
        .iter()
        .chain(&eq.drive_force)
        .all(|v| v.is_finite());
    if !pose_finite || !forces_finite || !eq.carrier.iter().all(|v| v.is_finite()) {
        return fail(Reason::NotConverged, 0, f64::NAN, 0.0);
    }
    let dpsi = wrap_angle(eq.psi - p[GAMMA2]).abs();
    if !within(dpsi, limits.psi_rad) {
        return fail(Reason::PlatformAngle, 0, dpsi, limits.psi_rad);
    }
    check_forces(eq, limits)?;
    check_closure(p, lengths, k, q, followers, eq, limits)?;
    check_balance(balance, eq, limits)?;
    let (dx, dy) = (eq.x - rigid.x, eq.y - rigid.y);
    if !within_norm(dx, dy, limits.rigid_mm) {
        return fail(Reason::FarFromRigid, 0, dx.hypot(dy), limits.rigid_mm);
    }
    Ok(())
}

/// |(a, b)| within `limit` as [`within`] of the hypot, compared squared: hypot, a fifth of
/// the checks, is only needed for the value a failure reports. False for NaN, a negative
/// limit, and where a² + b² overflows (a norm beyond 1e154, which fails any finite limit).
fn within_norm(a: f64, b: f64, limit: f64) -> bool {
    a * a + b * b <= limit * limit && limit >= 0.0
}

fn check_forces(eq: &Equilibrium, limits: &Limits) -> Result<(), Violation> {
    let max = limits.force_factor * NOMINAL_DRIVE_FORCE_N;
    for (i, f) in eq.rod_force.iter().enumerate() {
        if !within(f.abs(), max) {
            return fail(Reason::ForceLimit, i + 1, f.abs(), max);
        }
    }
    for (j, f) in eq.drive_force.iter().enumerate() {
        if !within(f.abs(), max) {
            return fail(Reason::ForceLimit, j + 1, f.abs(), max);
        }
    }
    Ok(())
}

/// Rod lengths against their forces at the solved carriers, and the carriers against the
/// encoders: an active rigid carrier exactly at q, a compliant one deflected by its force
/// (s − q = −f/c), a follower near its reading.
fn check_closure(
    p: &Params,
    lengths: &[f64; 5],
    k: &Stiffness,
    q: &[f64; 4],
    followers: Followers,
    eq: &Equilibrium,
    limits: &Limits,
) -> Result<(), Violation> {
    for (i, (rho, rod)) in lengths.iter().zip(&crate::params::RODS).enumerate() {
        let off = (rho - p[rod.l] - eq.rod_force[i] / k.rod[i]).abs();
        if !within(off, limits.closure_mm) {
            return fail(Reason::LoopClosure, i + 1, off, limits.closure_mm);
        }
    }
    for j in 0..4 {
        let s = eq.carrier[j];
        let (off, limit) = if followers[j] {
            ((s - q[j]).abs(), limits.follower_mm)
        } else {
            let deflection = k.carrier[j].map_or(0.0, |c| -eq.drive_force[j] / c);
            ((s - q[j] - deflection).abs(), limits.closure_mm)
        };
        if !within(off, limit) {
            return fail(Reason::LoopClosure, j + 1, off, limit);
        }
    }
    Ok(())
}

fn check_balance(balance: [f64; 3], eq: &Equilibrium, limits: &Limits) -> Result<(), Violation> {
    let largest = eq.rod_force.iter().fold(0.0f64, |m, f| m.max(f.abs()));
    let force_tol = 1.0 + limits.balance_rel * largest;
    let [fx, fy, mz] = balance;
    if !within_norm(fx, fy, force_tol) {
        return fail(Reason::ForceBalance, 0, fx.hypot(fy), force_tol);
    }
    // Moment about the TCP, N·mm: the same tolerance on a 1 m lever (the lever in mm).
    let moment_tol = force_tol * crate::units::mm_from_m(1.0);
    if !within(mz.abs(), moment_tol) {
        return fail(Reason::ForceBalance, 0, mz.abs(), moment_tol);
    }
    Ok(())
}
