//! Baseline redundant forward models without stiffness (thesis 5.1 and 5.2).

use super::guarded::fegm;
use super::spring::{ElasticError, Stiffness, ALL_ACTIVE};
use crate::geometry::{sensitivity, solve, Subsystem, X, Y};
use crate::params::{Model, Params};

/// A redundant forward model's answer: TCP (mm) and platform angle (rad).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RedundantPose {
    pub x: f64,
    pub y: f64,
    pub psi: f64,
}

/// Statistical method (5.1, [Marquet 03]): the weighted mean of the forward models of the
/// viable non-redundant subsystems, weights 1 / condition number of each subsystem's Jacobian
/// ∂(x, y)/∂(q_a, q_b). Subsystems that are singular at this pose are skipped.
pub fn statistical(p: &Params, model: Model, q: [f64; 4]) -> Result<RedundantPose, ElasticError> {
    let (mut sw, mut sx, mut sy, mut spsi) = (0.0, 0.0, 0.0, 0.0);
    let mut last_err = None;
    for sub in Subsystem::VIABLE {
        let Subsystem::Actuators(a, b) = sub else {
            continue;
        };
        let sol = match solve(p, model, sub, [q[a], q[b]]) {
            Ok(s) => s,
            Err(e) => {
                last_err = Some(e);
                continue;
            }
        };
        let sens = match sensitivity(p, model, sub, &sol) {
            Ok(s) => s,
            Err(e) => {
                last_err = Some(e);
                continue;
            }
        };
        let j = nalgebra::Matrix2::new(
            sens.dc_dk[(X, 0)],
            sens.dc_dk[(X, 1)],
            sens.dc_dk[(Y, 0)],
            sens.dc_dk[(Y, 1)],
        );
        let sv = j.singular_values();
        let cond = sv.max() / sv.min();
        if !cond.is_finite() {
            continue;
        }
        let w = 1.0 / cond;
        sw += w;
        sx += w * sol.x();
        sy += w * sol.y();
        spsi += w * sol.psi();
    }
    if sw == 0.0 {
        return Err(match last_err {
            Some(e) => ElasticError::Start(e),
            None => ElasticError::NotHeld,
        });
    }
    Ok(RedundantPose {
        x: sx / sw,
        y: sy / sw,
        psi: spsi / sw,
    })
}

/// Least-squares method (5.2, [Marquet 03]): the pose minimising ½ Σ r_i² over the five
/// loop closures with r_i = |A_i − B_i| − l_i and all four actuators at `q`. This is the
/// spring model with equal rod stiffness and rigid carriers, solved by the same Newton.
pub fn least_squares(p: &Params, q: [f64; 4]) -> Result<RedundantPose, ElasticError> {
    let unit = Stiffness {
        rod: [1.0; 5],
        carrier: [None; 4],
    };
    let eq = fegm(p, &unit, q, ALL_ACTIVE)?;
    Ok(RedundantPose {
        x: eq.x,
        y: eq.y,
        psi: eq.psi,
    })
}
