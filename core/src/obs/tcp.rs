//! Held-out TCP errors of the relative instruments, with their sensitivities to the effects.

use super::forward_solve::{forward, input_sensitivity, negated};
use super::row::PoseError;
use crate::campaign::{Campaign, Instrument};
use crate::effects::Corrections;
use crate::geometry::{Subsystem, X, Y};
use crate::params::{Model, Params};
use nalgebra::Vector2;

/// Whether a campaign has rows of the given kind.
pub fn has_forward_instruments(campaign: &Campaign) -> bool {
    campaign.poses.iter().any(|p| {
        matches!(
            p.instrument,
            Instrument::Dbb | Instrument::LiX | Instrument::LiY | Instrument::LiPsi
        )
    })
}

/// The coordinate a held-out TCP error is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TcpDirection {
    /// x of the machine frame.
    X,
    /// y of the machine frame.
    Y,
    /// The ball-bar's distance from its pivot.
    R,
}

impl TcpDirection {
    /// As the campaign's columns and the reports write it: `x`, `y`, `r`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::X => "x",
            Self::Y => "y",
            Self::R => "r",
        }
    }
}

impl std::fmt::Display for TcpDirection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One held-out TCP error: the model's relative TCP from the recorded actuators minus the
/// instrument's reading, in one coordinate.
#[derive(Clone, Debug, PartialEq)]
pub struct TcpError {
    /// Index of the pose in the campaign.
    pub pose: usize,
    /// The coordinate (the ball-bar's: its distance).
    pub direction: TcpDirection,
    /// Error, mm.
    pub value: f64,
    /// d value / d θ over the effects' parameters (empty without effects).
    pub d_theta: Vec<f64>,
}

/// TCP position error of held-out poses (µm-ready, mm here): for every non-reset pose of a
/// relative TCP instrument, the model's TCP from the recorded actuators (fgm of (q1, q4),
/// relative to the setup's reset pose) minus the instrument's reading, per measured coordinate
/// (x, y, or the ball-bar distance), without effects (no sensitivities).
pub fn tcp_errors(
    campaign: &Campaign,
    p: &Params,
    model: Model,
) -> Result<Vec<TcpError>, PoseError> {
    tcp_errors_with(campaign, p, model, &Corrections::default())
}

/// [`tcp_errors`] under the effects' corrections, with the errors' sensitivities to the
/// effects' parameters (to re-fit setup-local ones on held-out setups).
pub fn tcp_errors_with(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    corr: &Corrections,
) -> Result<Vec<TcpError>, PoseError> {
    let mut out = Vec::new();
    for setup in campaign.setups() {
        let Some(ri) = setup.reset else { continue };
        let reset = &campaign.poses[ri];
        for &i in &setup.poses {
            let pose = &campaign.poses[i];
            if pose.reset || !pose.instrument.is_relative() {
                continue;
            }
            let (dpose, dreset) = (corr.delta(i), corr.delta(ri));
            let (p_i, q_i) = dpose.applied(p, &pose.q);
            let (p_r, q_r) = dreset.applied(p, &reset.q);
            let now = forward(&p_i, model, Subsystem::NR, &q_i)
                .map_err(|e| PoseError::at(campaign, pose, e))?;
            // a reset pose that cannot be solved is blamed on its own line
            let zero = forward(&p_r, model, Subsystem::NR, &q_r)
                .map_err(|e| PoseError::at(campaign, reset, e))?;
            let (dx, dy) = (now.sol.c[X] - zero.sol.c[X], now.sol.c[Y] - zero.sol.c[Y]);
            let mut push = |direction, value, g: &[(usize, f64)], dm: Vector2<f64>| {
                let mut at_pose = input_sensitivity(&now, Subsystem::NR, g);
                at_pose.dm = dm;
                let at_reset = negated(input_sensitivity(&zero, Subsystem::NR, g));
                out.push(TcpError {
                    pose: i,
                    direction,
                    value,
                    d_theta: corr.theta_row(&[(i, at_pose), (ri, at_reset)]),
                });
            };
            if let Some(m) = pose.x {
                push(
                    TcpDirection::X,
                    dx - m - dpose.dm.x,
                    &[(X, 1.0)],
                    Vector2::new(-1.0, 0.0),
                );
            }
            if let Some(m) = pose.y {
                push(
                    TcpDirection::Y,
                    dy - m - dpose.dm.y,
                    &[(Y, 1.0)],
                    Vector2::new(0.0, -1.0),
                );
            }
            if let Some(m) = pose.r {
                let dist = dx.hypot(dy).max(1e-12);
                let g = [(X, dx / dist), (Y, dy / dist)];
                push(TcpDirection::R, dx.hypot(dy) - m, &g, Vector2::zeros());
            }
        }
    }
    Ok(out)
}
