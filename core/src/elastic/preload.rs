//! Compatibility test, predicted redundancy current and the thesis's "first approach" to the
//! internal preload (thesis 4.4 and the introduction of chapter 5).

use super::guarded::fegm;
use super::spring::{ElasticError, Equilibrium, Stiffness, ALL_ACTIVE};
use crate::geometry::{igm, rgm};
use crate::params::{Model, Params};
use nalgebra::{Matrix2, Vector2};

/// Result of the compatibility test at one pose (seed eq. 4.43).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Compatibility {
    /// Target TCP, mm.
    pub x: f64,
    pub y: f64,
    /// Actuator positions the controller commands: igm of its parameters, mm.
    pub q_commanded: [f64; 4],
    /// q2, q3 read in follower mode on the machine (rgm of the machine at the commanded q1,
    /// q4), mm.
    pub q_follower: [f64; 2],
    /// Δq2 = q2(model) − q2(measured), mm.
    pub dq2: f64,
    /// Δq3 = q3(model) − q3(measured), mm.
    pub dq3: f64,
    /// The machine with all four drives active at the commanded positions: pose, rod and drive
    /// forces; its [`Equilibrium::current`] is the predicted redundancy current.
    pub active: Equilibrium,
}

/// The compatibility test of a controller parameter set on a machine at (x, y): Δq2, Δq3 with
/// q2, q3 followers, then the redundancy current with all four drives active.
pub fn compatibility(
    machine: &Params,
    stiffness: &Stiffness,
    controller: &Params,
    controller_model: Model,
    x: f64,
    y: f64,
) -> Result<Compatibility, ElasticError> {
    let q = igm(controller, controller_model, x, y)?.q();
    let [q2m, q3m] = rgm(machine, Model::M29, q[0], q[3])?;
    let active = fegm(machine, stiffness, q, ALL_ACTIVE)?;
    Ok(Compatibility {
        x,
        y,
        q_commanded: q,
        q_follower: [q2m, q3m],
        dq2: q[1] - q2m,
        dq3: q[2] - q3m,
        active,
    })
}

/// Effect of offsets added to compatible actuator positions.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PreloadPlan {
    /// Target TCP, mm.
    pub x: f64,
    pub y: f64,
    /// Compatible actuator positions (igm of the parameters), mm.
    pub q_compatible: [f64; 4],
    /// Offsets added to q1..q4, mm.
    pub offsets: [f64; 4],
    /// The equilibrium with all four drives active at q_compatible + offsets.
    pub equilibrium: Equilibrium,
    /// TCP displacement caused by the preload (equilibrium − target), mm: what the controller
    /// must compensate.
    pub tcp_displacement: [f64; 2],
    /// Platform angle change, rad.
    pub psi_displacement: f64,
}

/// Equilibrium when `offsets` are added to the compatible positions igm(p, model, x, y).
pub fn offset_effect(
    p: &Params,
    stiffness: &Stiffness,
    model: Model,
    x: f64,
    y: f64,
    offsets: [f64; 4],
) -> Result<PreloadPlan, ElasticError> {
    let sol = igm(p, model, x, y)?;
    let qc = sol.q();
    let q = [0, 1, 2, 3].map(|i| qc[i] + offsets[i]);
    let eq = fegm(p, stiffness, q, ALL_ACTIVE)?;
    Ok(PreloadPlan {
        x,
        y,
        q_compatible: qc,
        offsets,
        equilibrium: eq,
        tcp_displacement: [eq.x - sol.x(), eq.y - sol.y()],
        psi_displacement: eq.psi - sol.psi(),
    })
}

/// The thesis's first approach: the offsets on q2, q3 that make drives 2 and 3 hold the
/// requested forces `target` = (f2, f3) in N at (x, y), and the TCP displacement they cause.
/// Newton on the two offsets with a finite-difference 2×2 Jacobian (the map is nearly
/// linear; 2-3 iterations).
pub fn preload_offsets(
    p: &Params,
    stiffness: &Stiffness,
    model: Model,
    x: f64,
    y: f64,
    target: [f64; 2],
) -> Result<PreloadPlan, ElasticError> {
    let f23 = |o: Vector2<f64>| -> Result<(Vector2<f64>, PreloadPlan), ElasticError> {
        let plan = offset_effect(p, stiffness, model, x, y, [0.0, o.x, o.y, 0.0])?;
        let f = plan.equilibrium.drive_force;
        Ok((Vector2::new(f[1], f[2]), plan))
    };
    let want = Vector2::new(target[0], target[1]);
    let mut o = Vector2::zeros();
    let h = 1e-3;
    for it in 0..20 {
        let (f, plan) = f23(o)?;
        let r = f - want;
        if r.amax() < 1e-6 * (1.0 + want.amax()) {
            return Ok(plan);
        }
        let (fa, _) = f23(o + Vector2::new(h, 0.0))?;
        let (fb, _) = f23(o + Vector2::new(0.0, h))?;
        let j = Matrix2::from_columns(&[(fa - f) / h, (fb - f) / h]);
        let step = j
            .lu()
            .solve(&r)
            .ok_or(ElasticError::Singular { iteration: it })?;
        o -= step;
    }
    Err(ElasticError::NotConverged {
        iterations: 20,
        step: f64::NAN,
        gradient: f64::NAN,
    })
}
