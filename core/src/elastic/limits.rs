//! What the plausibility checks speak of: the limits an equilibrium must keep, why one fails
//! them ([`Reason`], [`Violation`]) and the rigid pose it is held against. The spring model
//! reports a failed check with these, and the checks read the spring model's equilibrium:
//! both read this file, neither the other.

use std::f64::consts::{PI, TAU};
use std::fmt;

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
