//! The guarded elastic solve: the spring model's equilibrium, checked for plausibility against
//! the rigid model, warm-started where a previous sample allows and solved again cold where
//! the warm result fails. The one entry to the elastic model for the CLI, the calibrator
//! and the nodes.

use super::limits::{Limits, Reason, RigidPose, Violation};
use super::plausibility;
use super::spring::{
    rigid_start, solve_from, warm_start, ElasticError, Equilibrium, Followers, Solved, Stiffness,
};
use crate::geometry::frames;
use crate::params::Params;

/// Elasto-geometric forward model: the static equilibrium for commanded actuator positions
/// `q` (mm), parameters `p` and stiffness `k`, with drives in `followers` free. Starts from the
/// rigid forward model of an active pair; the result passes the plausibility checks with the
/// default [`Limits`] (else [`ElasticError::Implausible`]).
pub fn fegm(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
) -> Result<Equilibrium, ElasticError> {
    fegm_checked(p, k, q, followers, None, &Limits::default()).map(|s| s.eq)
}

/// [`fegm`] from a previous equilibrium (servo-rate use: the last sample is an excellent
/// start). A warm result that fails the plausibility checks is solved again cold.
pub fn fegm_from(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    previous: &Equilibrium,
) -> Result<Equilibrium, ElasticError> {
    fegm_checked(p, k, q, followers, Some(previous), &Limits::default()).map(|s| s.eq)
}

/// A checked elastic solve and how it was reached.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checked {
    /// The equilibrium; it passed every check.
    pub eq: Equilibrium,
    /// Solved from the rigid start (no previous equilibrium, or the warm solve was rejected).
    pub cold: bool,
    /// Why the warm-started solve was rejected, when it was (a solver failure counts as
    /// [`Reason::NotConverged`]).
    pub warm_rejected: Option<Violation>,
    /// The rigid forward model the result was checked against.
    pub rigid: RigidPose,
}

/// The one guarded entry to the elastic model (the CLI, the calibrator and the nodes all come
/// through here): warm-started from `previous` when given, checked with `limits`; a warm
/// result that fails is solved again from the rigid start and checked again. An error means
/// no plausible equilibrium: the caller falls back to the rigid model.
pub fn fegm_checked(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    previous: Option<&Equilibrium>,
    limits: &Limits,
) -> Result<Checked, ElasticError> {
    guarded(p, k, (q, followers), (previous, None), limits)
}

/// [`fegm_checked`] after the previous sample's checked solve (the servo-rate use): the solve
/// warm-started from its equilibrium, and the rigid reference's secant in ψ from its rigid ψ
/// (the reference stays that of the holding drives alone, independent of any elastic
/// solution: the same pose as from γ2, in fewer closures).
pub fn fegm_checked_after(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    previous: Option<&Checked>,
    limits: &Limits,
) -> Result<Checked, ElasticError> {
    let warm = previous.map_or((None, None), |c| (Some(&c.eq), Some(c.rigid.psi)));
    guarded(p, k, (q, followers), warm, limits)
}

/// The guarded solve of [`fegm_checked`], with the rigid reference's secant from `psi_warm`
/// where given.
fn guarded(
    p: &Params,
    k: &Stiffness,
    (q, followers): ([f64; 4], Followers),
    (previous, psi_warm): (Option<&Equilibrium>, Option<f64>),
    limits: &Limits,
) -> Result<Checked, ElasticError> {
    if !q.iter().all(|v| v.is_finite()) {
        return Err(ElasticError::NonFinite);
    }
    // The guides' frames once for the rigid model, the solve and the checks.
    let fr = frames(p);
    // The rigid model is both the reference of the checks and the cold start.
    let z0 = rigid_start(p, &fr, (&q, followers), psi_warm)?;
    let rigid = RigidPose {
        x: z0[0],
        y: z0[1],
        psi: z0[2],
    };
    let check = |sol: &Solved| {
        let rods = (&sol.lengths, sol.balance);
        plausibility::check_with(p, k, (&q, followers), &sol.eq, rods, &rigid, limits)
    };
    let mut warm_rejected = None;
    if let Some(prev) = previous {
        let rejection = match solve_from(p, &fr, k, q, followers, warm_start(&q, followers, prev)) {
            Ok(sol) => match check(&sol) {
                Ok(()) => {
                    return Ok(Checked {
                        eq: sol.eq,
                        cold: false,
                        warm_rejected: None,
                        rigid,
                    })
                }
                Err(v) => v,
            },
            Err(e) => solver_violation(&e),
        };
        warm_rejected = Some(rejection);
    }
    let sol = solve_from(p, &fr, k, q, followers, z0)?;
    check(&sol).map_err(ElasticError::Implausible)?;
    Ok(Checked {
        eq: sol.eq,
        cold: true,
        warm_rejected,
        rigid,
    })
}

/// A solver failure of the warm start, as the reason it was rejected.
fn solver_violation(e: &ElasticError) -> Violation {
    match e {
        ElasticError::Implausible(v) => *v,
        _ => Violation {
            reason: Reason::NotConverged,
            item: 0,
            value: f64::NAN,
            limit: 0.0,
        },
    }
}
