//! The drive-force rows (currents), their Jacobian and the force-position gains.

use super::context::Ctx;
use super::inverse::combine_into;
use super::row::{Direction, PoseError, ResetGain, Residual};
use crate::campaign::{Campaign, MeasuredPose};
use crate::effects::{Corrections, InputSensitivity};
use crate::elastic::{fegm, fegm_from, ElasticError, Equilibrium, Stiffness, ALL_ACTIVE};
use crate::geometry;
use crate::noise::{self, ForceModes, NoiseModel};
use crate::params::Row;
use crate::params::{Model, Params, N_PARAMS};
use nalgebra::Matrix4;

/// Step of the central differences of the force rows' Jacobian: small against the
/// tolerances (0.1 mm, 1 mrad), large against the equilibrium's convergence (1e-9 of a
/// force of ~100 N), on a nearly linear map (forces are stiffness times incompatibility).
fn force_step(i: usize) -> f64 {
    if crate::params::unit(i) == crate::params::Unit::Rad {
        1e-6
    } else {
        1e-3
    }
}

/// The drive forces of the elasto-geometric model with all four drives position-controlled
/// at `q` (parameters `p`, stiffness `k`) and their derivatives by the 29 parameters: central
/// differences of the equilibrium, warm-started from its own (from `warm` where given: the
/// previous sample of a stream).
pub fn force_jacobian(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    warm: Option<&Equilibrium>,
) -> Result<(Equilibrium, [Row; 4]), ElasticError> {
    let eq: Equilibrium = match warm {
        Some(w) => fegm_from(p, k, q, ALL_ACTIVE, w)?,
        None => fegm(p, k, q, ALL_ACTIVE)?,
    };
    let mut dp = [Row::zeros(); 4];
    for j in 0..N_PARAMS {
        let h = force_step(j);
        let at = |sign: f64| -> Result<[f64; 4], ElasticError> {
            let mut pj = *p;
            pj[j] += sign * h;
            Ok(fegm_from(&pj, k, q, ALL_ACTIVE, &eq)?.drive_force)
        };
        let (plus, minus) = (at(1.0)?, at(-1.0)?);
        for a in 0..4 {
            dp[a][j] = (plus[a] - minus[a]) / (2.0 * h);
        }
    }
    Ok((eq, dp))
}

/// Drive-force rows (thesis 4.4, used as measurements): with all four drives
/// position-controlled at the recorded positions, the elasto-geometric model's drive forces
/// minus the recorded ones, f1..f4 (N), with the default stiffness times 1 + the effects'
/// stiffness change. Their derivatives by the 29 parameters (and, with effects, by the
/// carrier positions) by central differences of the equilibrium, warm-started from the
/// pose's own; by the stiffness change exactly f / (1 + dk): uniformly scaled springs deform
/// alike, only their forces scale. The effects' columns are the chain rule through these
/// ([`Delta::chain`]): a temperature that lengthens a rod enters the forces as it enters
/// the geometry.
///
/// In the calibration's form the rows carry the drives' position noise too (errors in
/// variables: [`noise::DriveNoise`]) and are decorrelated ([`decorrelate_forces`]); in the
/// thesis's form they are the four forces with the currents' noise alone (the observability
/// tables of the currents).
pub(super) fn force_rows(
    ctx: &Ctx,
    i: usize,
    pose: &MeasuredPose,
    out: &mut Vec<Residual>,
) -> Result<(), ElasticError> {
    let d = ctx.corr.delta(i);
    let (p_i, q_i) = d.applied(ctx.p, &pose.q);
    let k = Stiffness::default().scaled(1.0 + d.dk);
    let (eq, dp) = force_jacobian(&p_i, &k, q_i, None)?;
    let mut sens = [InputSensitivity::default(); 4];
    for a in 0..4 {
        sens[a].dp = dp[a];
    }
    // the carrier positions matter only through an effect that moves them (a scale)
    if ctx.corr.n_params > 0 {
        let gains = force_position_gains(&p_i, &k, q_i, &eq)?;
        for (a, s) in sens.iter_mut().enumerate() {
            s.dq = std::array::from_fn(|b| gains[(a, b)]);
            s.dk = eq.drive_force[a] / (1.0 + d.dk);
        }
    }
    let parts = ctx.noise.force_parts();
    let mut rows: [Residual; 4] = std::array::from_fn(|a| Residual {
        pose: i,
        instrument: pose.instrument,
        direction: Direction::F(a),
        value: eq.drive_force[a] - pose.f[a],
        sigma: noise::sigma_of(&parts),
        parts,
        jacobian: sens[a].dp + ctx.corr.p_row(&[(i, sens[a])]),
        d_pcal: None,
        d_theta: ctx.corr.theta_row(&[(i, sens[a])]),
        reset_gain: ResetGain::zeros(),
    });
    if ctx.decorrelated {
        // at the fixed p_cal: combinations that moved with the fit would make the
        // Jacobian inexact (as [`fixed_gains`] for a 2-D instrument)
        let k = Stiffness::default();
        let eq = fegm(ctx.p_cal, &k, pose.q, ALL_ACTIVE)?;
        let gains = force_position_gains(ctx.p_cal, &k, pose.q, &eq)?;
        decorrelate_forces(&mut rows, &ctx.noise.drives().modes(&gains));
    }
    out.extend(rows);
    Ok(())
}

/// The derivatives of the four drive forces by the four carrier positions (N/mm; row a:
/// force a, column b: carrier b) at `q` under `p` and `k`, all drives position-controlled:
/// central differences of the equilibrium, warm-started from `eq`, its own at `q`. What an
/// encoder's error does to the forces ([`noise::DriveNoise`]).
pub fn force_position_gains(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    eq: &Equilibrium,
) -> Result<Matrix4<f64>, ElasticError> {
    // The central difference's step of a drive position: 1 µm, small against the preload's
    // curvature and large against the equilibrium's tolerance.
    const STEP_MM: f64 = 1e-3;
    let mut gains = Matrix4::zeros();
    for b in 0..4 {
        let at = |sign: f64| -> Result<[f64; 4], ElasticError> {
            let mut qb = q;
            qb[b] += sign * STEP_MM;
            Ok(fegm_from(p, k, qb, ALL_ACTIVE, eq)?.drive_force)
        };
        let (plus, minus) = (at(1.0)?, at(-1.0)?);
        for a in 0..4 {
            gains[(a, b)] = (plus[a] - minus[a]) / 2e-3;
        }
    }
    Ok(gains)
}

/// Replaces the four force rows of one pose by their combinations along `modes` (the
/// forces' noise diagonalised: [`noise::DriveNoise::modes`]), each with its own variance
/// parts: independent rows whatever the currents' and the encoders' levels, so that the
/// noise rounds estimate both.
fn decorrelate_forces(rows: &mut [Residual; 4], modes: &ForceModes) {
    let old = rows.clone();
    for (m, row) in rows.iter_mut().enumerate() {
        let w = modes.basis.column(m);
        combine_into(row, &old, |a| w[a], (Direction::FMode(m), modes.parts[m]));
    }
}

/// The drive-force rows of every pose of `campaign` with all four drives position-controlled,
/// whether or not forces were recorded (a pose without is read as zero force): the
/// observability of the currents on a planned design, where a machine consistent with `p`
/// has no preload to record.
pub fn force_residuals(
    campaign: &Campaign,
    p: &Params,
    corr: &Corrections,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PoseError> {
    let ctx = Ctx {
        p,
        p_cal: p,
        model: Model::M29,
        corr,
        noise,
        // the four forces as recorded, with the currents' noise alone
        decorrelated: false,
        shared: false,
        frames: geometry::frames(p),
    };
    let mut out = Vec::with_capacity(4 * campaign.poses.len());
    for (i, pose) in campaign.poses.iter().enumerate() {
        if pose.follower.iter().any(|f| *f) {
            continue;
        }
        force_rows(&ctx, i, pose, &mut out).map_err(|e| PoseError::at(campaign, pose, e))?;
    }
    Ok(out)
}
