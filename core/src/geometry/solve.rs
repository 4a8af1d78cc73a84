//! The entry points: solve any subsystem from its start (igm, fgm, rgm).

use super::closure::{equation_rods, frames, Frames, Trig};
use super::config::{q_var, GeometryError, Solution, Subsystem};
use super::fgm::{closed_fgm_at, fgm_closed, fgm_start, rod_in_assembly_mode, settled_psi_fgm};
use super::igm::{igm24, igm29, igm29_start, igm_start, WARM_PSI_RAD};
use super::newton::newton;
use crate::params::{Model, Params};

/// Solve a geometric model: the configuration that closes every loop given two known
/// variables. `known` holds (x, y) for [`Subsystem::Tcp`] or the two actuator positions.
pub fn solve(
    p: &Params,
    model: Model,
    sub: Subsystem,
    known: [f64; 2],
) -> Result<Solution, GeometryError> {
    if let Subsystem::Actuators(..) = sub {
        // its own finiteness check, closed form, then the general solver
        return fgm_with_frames(p, &frames(p), model, sub, known);
    }
    if !known.iter().all(|v| v.is_finite()) {
        return Err(GeometryError::NonFinite);
    }
    if model == Model::M24 && sub == Subsystem::Tcp {
        if let Some(sol) = igm24(p, known[0], known[1])? {
            return Ok(sol);
        }
    }
    if model == Model::M29 && sub == Subsystem::Tcp {
        if let Some(sol) = igm29(p, known[0], known[1]) {
            return Ok(sol);
        }
    }
    general(p, model, sub, known)
}

/// [`solve`] of a forward subsystem with the guides' frames given: the closed form
/// ([`fgm_closed`]) where its checks pass, else the general solver.
pub(crate) fn fgm_with_frames(
    p: &Params,
    frames: &Frames,
    model: Model,
    sub: Subsystem,
    known: [f64; 2],
) -> Result<Solution, GeometryError> {
    if !known.iter().all(|v| v.is_finite()) {
        return Err(GeometryError::NonFinite);
    }
    if let Subsystem::Actuators(a, b) = sub {
        if a < b && b < 4 {
            if let Some(sol) = fgm_closed(p, frames, model, (a, known[0]), (b, known[1])) {
                return Ok(sol);
            }
        }
    }
    general(p, model, sub, known)
}

/// The model-29 forward model of the subsystem (qa, qb) (drive indexes a < b < 4), its secant
/// in ψ started from `psi_warm` (the previous sample's rigid ψ) instead of γ2: the same
/// configuration as [`fgm_with_frames`] (the same root, settled to the same bound, with the
/// same closed checks), in fewer closures. Where the warm secant fails, a check fails, or ψ
/// settles more than [`WARM_PSI_RAD`] from `psi_warm`, [`fgm_with_frames`] decides.
pub(crate) fn fgm29_from(
    p: &Params,
    frames: &Frames,
    (a, b): (usize, usize),
    known: [f64; 2],
    psi_warm: f64,
) -> Result<Solution, GeometryError> {
    let ka = (a, known[0]);
    let kb = (b, known[1]);
    if a < b && b < 4 && psi_warm.is_finite() && known.iter().all(|v| v.is_finite()) {
        let warm = settled_psi_fgm(p, frames, (ka, kb), Some(psi_warm))
            .filter(|(psi, _)| (psi - psi_warm).abs() <= WARM_PSI_RAD)
            .and_then(|settled| closed_fgm_at(p, Model::M29, frames, ka, kb, settled));
        if let Some(sol) = warm {
            return Ok(sol);
        }
    }
    fgm_with_frames(p, frames, Model::M29, Subsystem::Actuators(a, b), known)
}

/// The general solver: Newton from the analytic start, then the assembly check of every
/// equation rod.
pub(super) fn general(
    p: &Params,
    model: Model,
    sub: Subsystem,
    known: [f64; 2],
) -> Result<Solution, GeometryError> {
    let start = match sub {
        Subsystem::Tcp if model == Model::M29 => igm29_start(p, known[0], known[1])?,
        Subsystem::Tcp => igm_start(p, known[0], known[1])?,
        Subsystem::Actuators(a, b) => fgm_start(p, a, b, known[0], known[1])?,
    };
    let sol = newton(p, model, sub, start)?;
    let t = Trig::new(p, &sol.c);
    for rod in equation_rods(model) {
        if !rod_in_assembly_mode(p, rod, &sol.c, &t) {
            return Err(GeometryError::AssemblyMode { rod: rod.number });
        }
    }
    Ok(sol)
}

/// Inverse geometric model: actuator positions (and ψ) of the TCP position (x, y).
pub fn igm(p: &Params, model: Model, x: f64, y: f64) -> Result<Solution, GeometryError> {
    solve(p, model, Subsystem::Tcp, [x, y])
}

/// Forward geometric model of the non-redundant subsystem (q1, q4).
pub fn fgm(p: &Params, model: Model, q1: f64, q4: f64) -> Result<Solution, GeometryError> {
    solve(p, model, Subsystem::NR, [q1, q4])
}

/// Redundant geometric model: (q2, q3) from (q1, q4).
pub fn rgm(p: &Params, model: Model, q1: f64, q4: f64) -> Result<[f64; 2], GeometryError> {
    let s = fgm(p, model, q1, q4)?;
    Ok([s.c[q_var(1)], s.c[q_var(2)]])
}
