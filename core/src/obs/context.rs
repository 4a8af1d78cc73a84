//! What every row of one evaluation shares, and what every pose of a relative setup reads of
//! its reset pose, solved once.

use super::forward_solve::{forward, Forward, FORWARD_SUBSYSTEMS};
use crate::campaign::{Instrument, MeasuredPose};
use crate::effects::Corrections;
use crate::geometry;
use crate::noise::NoiseModel;
use crate::params::{Model, Params};
use nalgebra::Vector2;

/// What every row of one evaluation shares.
pub(super) struct Ctx<'a> {
    pub(super) p: &'a Params,
    /// Parameters the rows' fixed combinations are built at (the calibration's start): a
    /// combination that moved with the parameters would make the Jacobian inexact.
    pub(super) p_cal: &'a Params,
    pub(super) model: Model,
    pub(super) corr: &'a Corrections,
    pub(super) noise: &'a NoiseModel,
    /// Whether a 2-D instrument's q rows are decorrelated (the calibration's form) or kept
    /// as the thesis writes them (its observability tables).
    pub(super) decorrelated: bool,
    /// Whether a relative setup's rows are made independent of the zero they share
    /// ([`share_reset`]; not in [`Form::PerPose`]).
    pub(super) shared: bool,
    /// The guides' frames of `p`, once per piece.
    pub(super) frames: geometry::Frames,
}

/// What every pose of a relative setup reads of its reset pose, solved once for a piece's
/// part of the setup instead of once per pose (issue 30: a campaign of small setups paid
/// them per pose): the same solves of the same inputs, so the rows are the same to the
/// bit. A solve that failed here is left to the pose that reads it, which makes it again
/// and reports its error as before, on the pose's line.
#[derive(Default)]
pub(super) struct AtReset {
    /// Through the redundant subsystem, at the reset's corrected inputs (2-D instruments).
    pub(super) nr: Option<Forward>,
    /// Through each of [`FORWARD_SUBSYSTEMS`] (forward instruments).
    pub(super) subs: [Option<Forward>; 2],
    /// The reset's TCP under `p_cal` without effects (the decorrelating gains).
    pub(super) tcp_cal: Option<Vector2<f64>>,
}

impl AtReset {
    /// What the poses of `reset`'s setup read of it: `nr`, its solve through the redundant
    /// subsystem at its corrected inputs `p_r`, `q_r`, and the instrument's other solves.
    pub(super) fn of(
        ctx: &Ctx,
        reset: &MeasuredPose,
        (p_r, q_r): (&Params, &[f64; 4]),
        nr: Forward,
    ) -> AtReset {
        use Instrument::{Dbb, Kgm, LiPsi, LiX, LiY, Lt};
        match reset.instrument {
            Lt | Kgm => AtReset {
                nr: Some(nr),
                tcp_cal: ctx
                    .decorrelated
                    .then(|| geometry::fgm(ctx.p_cal, ctx.model, reset.q[0], reset.q[3]).ok())
                    .flatten()
                    .map(|r| Vector2::new(r.x(), r.y())),
                ..AtReset::default()
            },
            Dbb | LiX | LiY | LiPsi => AtReset {
                subs: FORWARD_SUBSYSTEMS.map(|sub| forward(p_r, ctx.model, sub, q_r).ok()),
                ..AtReset::default()
            },
            _ => AtReset::default(),
        }
    }
}
