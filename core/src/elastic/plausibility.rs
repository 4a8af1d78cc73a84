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

use std::f64::consts::{PI, TAU};
use std::fmt;

use super::spring::{
    lengths_and_balance, Equilibrium, Followers, Stiffness, NOMINAL_DRIVE_FORCE_N,
};
use crate::geometry::frames;
use crate::params::{Params, GAMMA2};

/// Why an equilibrium is not physical. The discriminants are stable codes (for diagnostics
/// and logs); 0 means "plausible".
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[repr(u8)]
pub enum Reason {
    /// No finite elastic solution (the solver failed or left a NaN).
    NotConverged = 1,
    /// A rod's length disagrees with its force, or a carrier is not where its drive or
    /// encoder puts it.
    LoopClosure = 2,
    /// The platform is not in force and moment balance.
    ForceBalance = 3,
    /// A rod or drive force far beyond what the drives can give.
    ForceLimit = 4,
    /// ψ far from γ2: the platform is turned.
    PlatformAngle = 5,
    /// The TCP far from the rigid forward model of the holding drives.
    FarFromRigid = 6,
}

impl Reason {
    /// Every reason, in code order.
    pub const ALL: [Reason; 6] = [
        Reason::NotConverged,
        Reason::LoopClosure,
        Reason::ForceBalance,
        Reason::ForceLimit,
        Reason::PlatformAngle,
        Reason::FarFromRigid,
    ];

    /// The stable numeric code (1..=6).
    pub fn code(self) -> u8 {
        self as u8
    }

    /// snake_case name, as used in logs and /diagnostics keys.
    pub fn as_str(self) -> &'static str {
        match self {
            Reason::NotConverged => "not_converged",
            Reason::LoopClosure => "loop_closure",
            Reason::ForceBalance => "force_balance",
            Reason::ForceLimit => "force_limit",
            Reason::PlatformAngle => "platform_angle",
            Reason::FarFromRigid => "far_from_rigid",
        }
    }
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A failed check: which, where and by how much.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Violation {
    pub reason: Reason,
    /// Rod (1..=5) or drive (1..=4) concerned, 0 when none.
    pub item: u8,
    /// The offending value, in the unit of `limit` (mm, N, N·mm or rad).
    pub value: f64,
    /// The limit it exceeds.
    pub limit: f64,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = match self.reason {
            Reason::NotConverged => "no finite elastic solution",
            Reason::LoopClosure => "loop closure off",
            Reason::ForceBalance => "platform out of balance",
            Reason::ForceLimit => "force beyond the drives",
            Reason::PlatformAngle => "|ψ − γ2| too large",
            Reason::FarFromRigid => "TCP far from the rigid model",
        };
        write!(f, "{} ({what}", self.reason)?;
        if self.item > 0 {
            write!(f, ", item {}", self.item)?;
        }
        write!(f, "): {:.4e} > {:.4e}", self.value, self.limit)
    }
}

/// Limits of the checks. The defaults accept every equilibrium the drives can hold with
/// parameters within a few mm of the machine, and reject the wrong branches by orders of
/// magnitude (their ψ is off by π, their forces by 10⁴).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Limits {
    /// Rod length vs. force, and active carrier vs. its drive, mm. The solver stops at
    /// 1e-7 mm steps, so anything near this is not a solution of the model.
    pub closure_mm: f64,
    /// A follower's free carrier vs. its encoder, mm: the compatibility offset Δq, a few
    /// tenths of a mm for a calibrated machine, mm for nominal parameters.
    pub follower_mm: f64,
    /// Platform force residual allowed per N of the largest rod force (relative), plus 1 N;
    /// the moment limit is this force times 1 m.
    pub balance_rel: f64,
    /// Largest |rod or drive force| as a multiple of the nominal drive force (8,600 N).
    pub force_factor: f64,
    /// Largest |ψ − γ2|, rad (wrapped). The parallel-holder keeps ψ within a few mrad.
    pub psi_rad: f64,
    /// Largest distance of the TCP from the rigid forward model, mm. 10× the nominal force
    /// on the default stiffness deflects the TCP by about 1 mm.
    pub rigid_mm: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            closure_mm: 1e-3,
            follower_mm: 20.0,
            balance_rel: 1e-6,
            force_factor: 10.0,
            psi_rad: 0.01,
            rigid_mm: 2.0,
        }
    }
}

/// Angle wrapped to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let r = a.rem_euclid(TAU);
    if r > PI {
        r - TAU
    } else {
        r
    }
}

/// The rigid reference pose (x, y mm, ψ rad) an equilibrium is checked against.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RigidPose {
    pub x: f64,
    pub y: f64,
    pub psi: f64,
}

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
    // Moment about the TCP, N·mm: the same tolerance on a 1 m lever.
    let moment_tol = force_tol * 1000.0;
    if !within(mz.abs(), moment_tol) {
        return fail(Reason::ForceBalance, 0, mz.abs(), moment_tol);
    }
    Ok(())
}
