//! The forward solves behind a pose's rows: a subsystem's configuration under the effects'
//! corrections, and its sensitivities.

use crate::effects::InputSensitivity;
use crate::geometry::{self, GeometryError, Solution, Subsystem};
use crate::params::{Model, Params};

/// The forward subsystems used by forward calibration rows (thesis 4.2.1).
pub const FORWARD_SUBSYSTEMS: [Subsystem; 2] =
    [Subsystem::Actuators(0, 3), Subsystem::Actuators(2, 3)];

/// A solved forward model with its parameter and actuator sensitivities.
pub(super) struct Forward {
    pub(super) sol: Solution,
    pub(super) sens: geometry::Sensitivity,
}

impl Forward {
    pub(super) fn zeros() -> Forward {
        Forward {
            sol: Solution {
                c: geometry::Config::zeros(),
                iterations: 0,
                residual: 0.0,
            },
            sens: geometry::Sensitivity::zeros(),
        }
    }
}

pub(super) fn forward(
    p: &Params,
    model: Model,
    sub: Subsystem,
    q: &[f64; 4],
) -> Result<Forward, GeometryError> {
    let mut f = Forward {
        sol: solve_forward(p, model, sub, q)?,
        sens: geometry::Sensitivity::zeros(),
    };
    geometry::sensitivity_into(p, model, sub, &f.sol, &mut f.sens)?;
    Ok(f)
}

/// The configuration of a forward subsystem `sub` at the actuator positions `q`.
fn solve_forward(
    p: &Params,
    model: Model,
    sub: Subsystem,
    q: &[f64; 4],
) -> Result<Solution, GeometryError> {
    let Subsystem::Actuators(a, b) = sub else {
        unreachable!("forward rows use actuator subsystems")
    };
    geometry::solve(p, model, sub, [q[a], q[b]])
}

/// Sensitivity to the pose's inputs of Σ g_v · c_v of a forward solve through `sub`.
pub(super) fn input_sensitivity(
    f: &Forward,
    sub: Subsystem,
    g: &[(usize, f64)],
) -> InputSensitivity {
    let mut s = InputSensitivity::default();
    let Subsystem::Actuators(a, b) = sub else {
        return s;
    };
    for &(v, w) in g {
        s.dp += f.sens.dc_dp.row(v).transpose() * w;
        s.dq[a] += f.sens.dc_dk[(v, 0)] * w;
        s.dq[b] += f.sens.dc_dk[(v, 1)] * w;
    }
    s
}

/// The same sensitivity with the opposite sign (the reset pose of a relative value).
pub(super) fn negated(mut s: InputSensitivity) -> InputSensitivity {
    s.dp = -s.dp;
    s.dq = s.dq.map(|v| -v);
    s.dm = -s.dm;
    s.dpsi = -s.dpsi;
    s.dk = -s.dk;
    s
}

/// Squared gain from the known actuators' encoders to configuration variable `v`.
pub(super) fn encoder_gain2(f: &Forward, v: usize) -> f64 {
    f.sens.dc_dk[(v, 0)].powi(2) + f.sens.dc_dk[(v, 1)].powi(2)
}
