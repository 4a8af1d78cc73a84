//! Inverse calibration rows (eq. 4.30) of a laser tracker or grid encoder, decorrelated through
//! the drives' gains.

use super::context::{AtReset, Ctx};
use super::forward_solve::{forward, input_sensitivity};
use super::reset::complement;
use super::row::{reset_gain, Direction, ResetGain, Residual};
use crate::campaign::MeasuredPose;
use crate::effects::InputSensitivity;
use crate::geometry::{self, q_var, GeometryError, Subsystem, X, Y};
use crate::noise::{self, NoiseModel, Parts, XyInstrument};
use crate::params::Row;
use nalgebra::Vector2;

/// Inverse calibration rows (eq. 4.30) of a laser-tracker or grid-encoder pose.
pub(super) fn inverse_rows(
    ctx: &Ctx,
    xy: XyInstrument,
    (i, pose): (usize, &MeasuredPose),
    ((ri, reset), at): ((usize, &MeasuredPose), &AtReset),
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    let (Some(mx), Some(my)) = (pose.x, pose.y) else {
        return Ok(());
    };
    let dpose = ctx.corr.delta(i);
    let own;
    let r = if let Some(r) = &at.nr {
        r
    } else {
        let (p_r, q_r) = ctx.corr.delta(ri).applied(ctx.p, &reset.q);
        own = forward(&p_r, ctx.model, Subsystem::NR, &q_r)?;
        &own
    };
    let (x, y) = (mx + dpose.dm.x + r.sol.c[X], my + dpose.dm.y + r.sol.c[Y]);
    let (p_i, q_i) = dpose.applied(ctx.p, &pose.q);
    let inv = geometry::solve(&p_i, ctx.model, Subsystem::Tcp, [x, y])?;
    let s = geometry::sensitivity(&p_i, ctx.model, Subsystem::Tcp, &inv)?;
    let first = out.len();
    for (a, &q_a) in q_i.iter().enumerate() {
        let v = q_var(a);
        let g = Vector2::new(s.dc_dk[(v, 0)], s.dc_dk[(v, 1)]);
        // dq/dp = ∂igm/∂p + ∂igm/∂X · d fgm(Q_reset)/dp
        let at_reset = input_sensitivity(r, Subsystem::NR, &[(X, g.x), (Y, g.y)]);
        let mut at_pose = InputSensitivity {
            dp: s.dc_dp.row(v).transpose(),
            dm: g,
            ..Default::default()
        };
        at_pose.dq[a] = -1.0;
        let parts = noise::add(
            ctx.noise.xy_parts(xy, Vector2::new(x, y), g),
            ctx.noise.encoder_parts(1.0),
        );
        out.push(Residual {
            pose: i,
            instrument: pose.instrument,
            direction: Direction::Q(a),
            value: inv.c[v] - q_a,
            sigma: noise::sigma_of(&parts),
            parts,
            jacobian: at_pose.dp + at_reset.dp + ctx.corr.p_row(&[(i, at_pose), (ri, at_reset)]),
            d_pcal: None,
            d_theta: ctx.corr.theta_row(&[(i, at_pose), (ri, at_reset)]),
            // the reset's reading error enters as the pose's own does, through X
            reset_gain: reset_gain(g, &at_reset.dq),
        });
    }
    if ctx.decorrelated {
        let (g_fixed, tcp) = fixed_gains(ctx, mx, my, (&reset.q, at.tcp_cal))?;
        let (ux, uy) = match xy {
            XyInstrument::Lt => ctx.noise.beam_frame(tcp),
            XyInstrument::Kgm => (Vector2::x(), Vector2::y()),
        };
        decorrelate(&mut out[first..], &g_fixed, ux, uy, ctx.noise, xy, tcp);
    }
    Ok(())
}

/// The gains dq/dX of the four drives at the recorded TCP, under the parameters `p_cal`
/// (fixed during a calibration) and without effects: the decorrelating combinations stay
/// the same while the parameters move, so the rows' Jacobian is exact.
fn fixed_gains(
    ctx: &Ctx,
    mx: f64,
    my: f64,
    (q_reset, reset_cal): (&[f64; 4], Option<Vector2<f64>>),
) -> Result<([Vector2<f64>; 4], Vector2<f64>), GeometryError> {
    let r = if let Some(r) = reset_cal {
        r
    } else {
        let r = geometry::fgm(ctx.p_cal, ctx.model, q_reset[0], q_reset[3])?;
        Vector2::new(r.x(), r.y())
    };
    let tcp = Vector2::new(mx + r.x, my + r.y);
    let inv = geometry::solve(ctx.p_cal, ctx.model, Subsystem::Tcp, [tcp.x, tcp.y])?;
    let s = geometry::sensitivity(ctx.p_cal, ctx.model, Subsystem::Tcp, &inv)?;
    let g = [0, 1, 2, 3].map(|a| {
        let v = q_var(a);
        Vector2::new(s.dc_dk[(v, 0)], s.dc_dk[(v, 1)])
    });
    Ok((g, tcp))
}

/// Replace the four q rows of one 2-D instrument pose (rows r = G e + n: G the 4 × 2
/// derivative of the drives by the TCP, e the instrument's error, n the encoders') by four
/// uncorrelated rows with a meaning: the TCP misfit −(GᵀG)⁻¹Gᵀ r along `u` and `v` (mm;
/// model minus measured), and the two combinations Uᵀ r orthogonal to G's columns, which the
/// instrument cannot reach (encoder noise only). Correlated rows counted as independent make
/// χ² and F-tests overconfident; these are independent up to the encoders' small share in
/// the misfit rows.
fn decorrelate(
    rows: &mut [Residual],
    g: &[Vector2<f64>; 4],
    u: Vector2<f64>,
    v: Vector2<f64>,
    noise: &NoiseModel,
    instrument: XyInstrument,
    tcp: Vector2<f64>,
) {
    if rows.len() != 4 {
        return;
    }
    let gm = nalgebra::Matrix4x2::from_rows(&[
        g[0].transpose(),
        g[1].transpose(),
        g[2].transpose(),
        g[3].transpose(),
    ]);
    let Some(gtg_inv) = (gm.transpose() * gm).try_inverse() else {
        return; // a singular pose: keep the q rows
    };
    let a = gtg_inv * gm.transpose(); // 2 × 4
                                      // orthonormal basis of the complement of G's columns
    let svd = gm.svd(true, false);
    let Some(uf) = svd.u else { return };
    let full = nalgebra::Matrix4::from_fn(|r, c| if c < 2 { uf[(r, c)] } else { 0.0 });
    let comp = complement(&full);
    let weights: [(Direction, nalgebra::RowVector4<f64>); 4] = [
        (Direction::Along, -(u.transpose() * a)),
        (Direction::Across, -(v.transpose() * a)),
        (Direction::Compat(0), comp[0]),
        (Direction::Compat(1), comp[1]),
    ];
    let old: Vec<Residual> = rows.to_vec();
    for (row, (direction, w)) in rows.iter_mut().zip(weights) {
        // wᵀ G is the row's gain on the instrument's (x, y) error; |w|² on the encoders'
        let gain = Vector2::new((w * gm.column(0))[0], (w * gm.column(1))[0]);
        let parts = noise::add(
            noise.xy_parts(instrument, tcp, gain),
            noise.encoder_parts(w.norm_squared()),
        );
        combine_into(row, &old, |k| w[k], (direction, parts));
    }
}

/// `row` made the combination Σ_k w(k) old_k of a pose's rows (value, parameters' and
/// effects' derivatives), with its own direction and variance parts: one decorrelated row.
pub(super) fn combine_into(
    row: &mut Residual,
    old: &[Residual],
    w: impl Fn(usize) -> f64,
    (direction, parts): (Direction, Parts),
) {
    let mut value = 0.0;
    let mut jac = Row::zeros();
    let mut reset_gain = ResetGain::zeros();
    let mut d_theta = vec![0.0; old[0].d_theta.len()];
    for (k, o) in old.iter().enumerate() {
        value += w(k) * o.value;
        jac += o.jacobian * w(k);
        reset_gain += o.reset_gain * w(k);
        for (d, od) in d_theta.iter_mut().zip(&o.d_theta) {
            *d += w(k) * od;
        }
    }
    row.direction = direction;
    row.value = value;
    row.jacobian = jac;
    row.d_theta = d_theta;
    row.reset_gain = reset_gain;
    row.sigma = noise::sigma_of(&parts);
    row.parts = parts;
}
