//! Forward calibration rows (eq. 4.31), their second step (eq. 4.32) and self-calibration rows
//! (eq. 4.37).

use super::context::{AtReset, Ctx};
use super::forward_solve::{
    encoder_gain2, forward, input_sensitivity, negated, Forward, FORWARD_SUBSYSTEMS,
};
use super::row::{reset_gain, Direction, ResetGain, Residual};
use crate::campaign::{Instrument, MeasuredPose};
use crate::geometry::{self, q_var, GeometryError, Subsystem, PSI, X, Y};
use crate::noise;
use crate::params::Row;
use crate::params::{Params, D1, D2, GAMMA1, GAMMA2};
use nalgebra::Vector2;

/// Forward calibration rows (eq. 4.31): relative distance, coordinate or angle through each
/// forward subsystem.
pub(super) fn forward_rows(
    ctx: &Ctx,
    i: usize,
    pose: &MeasuredPose,
    ((ri, reset), at): ((usize, &MeasuredPose), &AtReset),
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    let (dpose, dreset) = (ctx.corr.delta(i), ctx.corr.delta(ri));
    let (p_i, q_i) = dpose.applied(ctx.p, &pose.q);
    let (p_r, q_r) = dreset.applied(ctx.p, &reset.q);
    for (sub, solved) in FORWARD_SUBSYSTEMS.into_iter().zip(&at.subs) {
        let now = forward(&p_i, ctx.model, sub, &q_i)?;
        let own;
        let zero = if let Some(zero) = solved {
            zero
        } else {
            own = forward(&p_r, ctx.model, sub, &q_r)?;
            &own
        };
        let d = |v: usize| now.sol.c[v] - zero.sol.c[v];
        // the reset pose's encoders are the whole setup's: in its shared part
        let var = |v: usize| encoder_gain2(&now, v);
        let inst = pose.instrument;
        // the value as Σ g_v · Δc_v − (measured + dm_w): g has two terms (x, y of the
        // ball-bar's direction); a single coordinate pads it with a zero-weight term
        let (direction, value, g, w, var_enc) = match inst {
            Instrument::Dbb => {
                let Some(r) = pose.r else { return Ok(()) };
                let (dx, dy) = (d(X), d(Y));
                let dist = dx.hypot(dy);
                if dist < 1e-9 {
                    continue;
                }
                let (ux, uy) = (dx / dist, dy / dist);
                let var_enc = ux * ux * var(X) + uy * uy * var(Y);
                let g = [(X, ux), (Y, uy)];
                (
                    Direction::R(a_of(sub), b_of(sub)),
                    dist - r,
                    g,
                    None,
                    var_enc,
                )
            }
            // one coordinate relative to the reset pose: x, y or ψ
            Instrument::LiX | Instrument::LiY | Instrument::LiPsi => {
                let (v, measured, direction, w) = match inst {
                    Instrument::LiX => (X, pose.x, Direction::X(a_of(sub), b_of(sub)), Some(0)),
                    Instrument::LiY => (Y, pose.y, Direction::Y(a_of(sub), b_of(sub)), Some(1)),
                    _ => (PSI, pose.psi, Direction::Psi(a_of(sub), b_of(sub)), None),
                };
                let Some(m) = measured else { return Ok(()) };
                // the reading's correction: x or y of dm, or dpsi for the angle
                let dm = w.map_or(dpose.dpsi, |k| dpose.dm[k]);
                (direction, d(v) - m - dm, [(v, 1.0), (v, 0.0)], w, var(v))
            }
            _ => return Ok(()),
        };
        let mut at_pose = input_sensitivity(&now, sub, &g);
        match (w, direction) {
            (Some(k), _) => at_pose.dm[k] = -1.0,
            (None, Direction::Psi(..)) => at_pose.dpsi = -1.0,
            (None, _) => {}
        }
        let at_reset = negated(input_sensitivity(zero, sub, &g));
        let parts = noise::add(
            ctx.noise.scalar_parts(inst, 1.0),
            ctx.noise.encoder_parts(var_enc),
        );
        out.push(Residual {
            pose: i,
            instrument: inst,
            direction,
            value,
            sigma: noise::sigma_of(&parts),
            parts,
            jacobian: at_pose.dp + at_reset.dp + ctx.corr.p_row(&[(i, at_pose), (ri, at_reset)]),
            d_pcal: None,
            d_theta: ctx.corr.theta_row(&[(i, at_pose), (ri, at_reset)]),
            // an interferometer is zeroed on a reading; a ball-bar's pivot is where the
            // machine stood, read by no instrument
            reset_gain: reset_gain(
                if inst == Instrument::Dbb {
                    Vector2::zeros()
                } else {
                    Vector2::x()
                },
                &at_reset.dq,
            ),
        });
    }
    Ok(())
}

fn a_of(sub: Subsystem) -> usize {
    match sub {
        Subsystem::Actuators(a, _) => a,
        Subsystem::Tcp => 0,
    }
}

fn b_of(sub: Subsystem) -> usize {
    match sub {
        Subsystem::Actuators(_, b) => b,
        Subsystem::Tcp => 0,
    }
}

/// Self-calibration rows (eq. 4.37): followers q2, q3 against rgm(q1, q4).
pub(super) fn self_rows(
    ctx: &Ctx,
    (i, pose): (usize, &MeasuredPose),
    f: &mut Forward,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    // without effects the pose's inputs are the machine's and the recorded positions
    // themselves: no correction (0.5 kB) built, added and copied per pose
    let own;
    let (p_i, q_i) = if ctx.corr.is_empty() {
        (ctx.p, pose.q)
    } else {
        own = ctx.corr.delta(i).applied(ctx.p, &pose.q);
        (&own.0, own.1)
    };
    // the guides' frames of the piece's machine where the correction leaves its guides as
    // they are (every pose without effects): two sin_cos less per pose
    let same_guides = [D1, GAMMA1, D2, GAMMA2]
        .iter()
        .all(|&k| p_i[k].to_bits() == ctx.p[k].to_bits());
    let mine;
    let frames = if same_guides {
        &ctx.frames
    } else {
        mine = geometry::frames(p_i);
        &mine
    };
    let sub = Subsystem::NR;
    f.sol = geometry::fgm_with_frames(p_i, frames, ctx.model, sub, [q_i[0], q_i[3]])?;
    // only the followers' rows of the sensitivities: what these rows read
    let vars = [q_var(1), q_var(2)];
    geometry::sensitivity_rows_into(p_i, ctx.model, (sub, &f.sol), frames, &vars, &mut f.sens)?;
    for a in [1, 2] {
        let v = q_var(a);
        // the follower's own encoder and those of q1, q4 through rgm
        let parts = ctx.noise.encoder_parts(1.0 + encoder_gain2(f, v));
        // the sensitivity to the pose's inputs only where effects read it: without, the
        // row's derivatives are the solve's own (1.2 kB less copied per row)
        let (d_theta, through) = if ctx.corr.n_params == 0 {
            (Vec::new(), Row::zeros())
        } else {
            let mut at_pose = input_sensitivity(f, Subsystem::NR, &[(v, 1.0)]);
            at_pose.dq[a] -= 1.0;
            (
                ctx.corr.theta_row(&[(i, at_pose)]),
                ctx.corr.p_row(&[(i, at_pose)]),
            )
        };
        out.push(Residual {
            pose: i,
            instrument: pose.instrument,
            direction: Direction::Q(a),
            value: f.sol.c[v] - q_i[a],
            sigma: noise::sigma_of(&parts),
            parts,
            jacobian: f.sens.dc_dp.row(v).transpose() + through,
            d_pcal: None,
            d_theta,
            reset_gain: ResetGain::zeros(),
        });
    }
    Ok(())
}

/// Second step of the forward instruments (eq. 4.32): X_e = fgm(Q_nr, P_cal), q2 = igm(X_e, P).
/// The effects' corrections apply to both models, with their parameters held fixed.
pub(super) fn virtual_q2_row(
    ctx: &Ctx,
    i: usize,
    pose: &MeasuredPose,
    p_cal: &Params,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    use Instrument::{Dbb, LiPsi, LiX, LiY};
    if !matches!(pose.instrument, Dbb | LiX | LiY | LiPsi) {
        return Ok(());
    }
    let d = ctx.corr.delta(i);
    let (p_i, q_i) = d.applied(ctx.p, &pose.q);
    let (p_cal_i, _) = d.applied(p_cal, &pose.q);
    let model = ctx.model;
    let xe = geometry::fgm(&p_cal_i, model, q_i[0], q_i[3])?;
    let xe_sens = geometry::sensitivity(&p_cal_i, model, Subsystem::NR, &xe)?;
    let inv = geometry::igm(&p_i, model, xe.x(), xe.y())?;
    let s = geometry::sensitivity(&p_i, model, Subsystem::Tcp, &inv)?;
    let v = q_var(1);
    let d_pcal: Row = (xe_sens.dc_dp.row(X) * s.dc_dk[(v, 0)]
        + xe_sens.dc_dp.row(Y) * s.dc_dk[(v, 1)])
        .transpose();
    out.push(Residual {
        pose: i,
        instrument: pose.instrument,
        direction: Direction::VirtualQ2,
        value: inv.c[v] - q_i[1],
        sigma: ctx.noise.encoder_mm * 2f64.sqrt(),
        parts: ctx.noise.encoder_parts(2.0),
        jacobian: s.dc_dp.row(v).transpose(),
        d_pcal: Some(Box::new(d_pcal)),
        d_theta: vec![0.0; ctx.corr.n_params],
        reset_gain: ResetGain::zeros(),
    });
    Ok(())
}
