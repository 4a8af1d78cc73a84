//! The two ways the thesis adapts the finite-element model to a redundant mechanism whose
//! parameters do not fit together, and the reusable model that solves either.

use super::assembly::{AssemblyStructure, Solver};
use super::error::FeError;
use super::machine::{build, FeStiffness, Layout, Placement};
use crate::elastic::spring::{Followers, NOMINAL_DRIVE_FORCE_N};
use crate::geometry::{self, carrier_joint, platform_joint, Solution, Subsystem};
use crate::params::{Model, Params, RODS};
use nalgebra::Vector2;

/// How the incompatibility enters the linear model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum FeMethod {
    /// Carriers at their commanded positions; a rod that does not fit its gap gets the misfit
    /// l_i − |A_i − B_i| as an initial elongation (a "thermal" strain).
    ThermoMechanical,
    /// Carriers where the rods fit (the rigid model of the active pair); each other active
    /// drive is displaced from there to its command.
    ActuatorDisplacements,
}

/// A finite-element equilibrium.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FeEquilibrium {
    pub method: FeMethod,
    /// Rigid pose the mesh lies on (model-29 fgm of the first viable active pair): x, y (mm),
    /// ψ (rad).
    pub reference: [f64; 3],
    /// Carrier positions of the mesh, mm.
    pub reference_carrier: [f64; 4],
    /// TCP displacement from the reference: x, y (mm), ψ (rad).
    pub tcp_displacement: [f64; 3],
    /// Deformed platform pose: reference + displacement.
    pub x: f64,
    pub y: f64,
    pub psi: f64,
    /// Axial force of rods 1..=5, N, positive in tension.
    pub rod_force: [f64; 5],
    /// Drive forces f1..f4, N, positive when the drive pushes its carrier towards larger q; 0
    /// for a follower.
    pub drive_force: [f64; 4],
    /// Initial elongations imposed (thermo-mechanical method), mm.
    pub rod_elongation: [f64; 5],
    /// Drive displacements imposed (actuator-displacements method), mm.
    pub drive_displacement: [f64; 4],
    /// Sum of the loads the rods exert on the platform: F_x, F_y (N) and the moment about the
    /// TCP (N·mm), on the undeformed geometry (the linear model's equilibrium).
    pub platform_balance: [f64; 3],
}

impl FeEquilibrium {
    /// Redundancy currents, % of the nominal 8,600 N, signed like the drive forces.
    pub fn current(&self) -> [f64; 4] {
        self.drive_force.map(|f| f / NOMINAL_DRIVE_FORCE_N * 100.0)
    }
    /// Largest |current| over the drives, %.
    pub fn max_current(&self) -> f64 {
        self.current().iter().fold(0.0, |m, c| m.max(c.abs()))
    }
}

/// The finite-element model with its structure and solver buffers: repeated solves allocate
/// nothing once the first has sized them.
#[derive(Clone, Debug)]
pub struct FeModel {
    stiffness: FeStiffness,
    structure: AssemblyStructure,
    solver: Solver,
}

impl FeModel {
    pub fn new(stiffness: FeStiffness) -> Result<FeModel, FeError> {
        stiffness.validate()?;
        Ok(FeModel {
            stiffness,
            structure: AssemblyStructure::new(),
            solver: Solver::new(),
        })
    }

    pub fn stiffness(&self) -> &FeStiffness {
        &self.stiffness
    }

    /// The structure of the last solve (for inspection).
    pub fn structure(&self) -> &AssemblyStructure {
        &self.structure
    }

    /// Equilibrium of the machine `p` with drives commanded to `q` (mm), `followers` free, the
    /// incompatibility imposed by `method`.
    pub fn solve(
        &mut self,
        p: &Params,
        q: [f64; 4],
        followers: Followers,
        method: FeMethod,
    ) -> Result<FeEquilibrium, FeError> {
        if !(q.iter().all(|v| v.is_finite()) && p.0.iter().all(|v| v.is_finite())) {
            return Err(FeError::NonFinite);
        }
        let rigid = reference(p, &q, followers)?;
        let placement = place(p, &q, followers, &rigid, method);
        let layout = build(&mut self.structure, p, &self.stiffness, &placement);
        self.solver.solve(&self.structure)?;
        self.finish(method, &placement, &layout)
    }

    fn finish(
        &self,
        method: FeMethod,
        placement: &Placement,
        layout: &Layout,
    ) -> Result<FeEquilibrium, FeError> {
        let (s, sol) = (&self.structure, &self.solver);
        let u = sol.node_displacement(s, layout.tcp);
        let tcp = s.node(layout.tcp).position;
        let mut rod_force = [0.0; 5];
        let mut balance = [0.0; 3];
        for ((force, &rod), &joint) in rod_force
            .iter_mut()
            .zip(&layout.rod)
            .zip(&layout.platform_joint)
        {
            *force = sol.axial_force(s, rod)?;
            // The rod's beam runs from its platform end (node a) to its carrier end.
            let load = sol.beam_loads_on_nodes(s, rod)?;
            let arm = s.node(joint).position - tcp;
            balance[0] += load[0];
            balance[1] += load[1];
            balance[2] += arm.x * load[1] - arm.y * load[0] + load[2];
        }
        let drive_force = layout.drive.map(|d| d.map_or(0.0, |d| sol.reaction(d)));
        let [x, y, psi] = placement.pose;
        Ok(FeEquilibrium {
            method,
            reference: placement.pose,
            reference_carrier: placement.carrier,
            tcp_displacement: [u.x, u.y, u.z],
            x: x + u.x,
            y: y + u.y,
            psi: psi + u.z,
            rod_force,
            drive_force,
            rod_elongation: placement.rod_elongation,
            drive_displacement: placement.drive_displacement,
            platform_balance: balance,
        })
    }
}

/// One-shot [`FeModel::solve`].
pub fn fe_solve(
    p: &Params,
    k: &FeStiffness,
    q: [f64; 4],
    followers: Followers,
    method: FeMethod,
) -> Result<FeEquilibrium, FeError> {
    FeModel::new(*k)?.solve(p, q, followers, method)
}

/// Rigid reference: the model-29 forward model of the first viable subsystem whose two drives
/// are active (the same start as the spring model's), at their commanded positions.
fn reference(p: &Params, q: &[f64; 4], followers: Followers) -> Result<Solution, FeError> {
    for sub in Subsystem::VIABLE {
        if let Subsystem::Actuators(a, b) = sub {
            if followers[a] || followers[b] {
                continue;
            }
            return Ok(geometry::solve(p, Model::M29, sub, [q[a], q[b]])?);
        }
    }
    Err(FeError::NotHeld)
}

/// Mesh position and loading of each method. The pair's drives sit at their commands in both
/// (the rigid solve holds them there exactly); followers sit where the rods fit.
fn place(
    p: &Params,
    q: &[f64; 4],
    followers: Followers,
    rigid: &Solution,
    method: FeMethod,
) -> Placement {
    let fit = rigid.q();
    let pose = [rigid.x(), rigid.y(), rigid.psi()];
    let mut placement = Placement {
        pose,
        carrier: fit,
        rod_elongation: [0.0; 5],
        drive_displacement: [0.0; 4],
        followers,
    };
    for j in 0..4 {
        if followers[j] {
            continue;
        }
        match method {
            FeMethod::ActuatorDisplacements => placement.drive_displacement[j] = q[j] - fit[j],
            FeMethod::ThermoMechanical => placement.carrier[j] = q[j],
        }
    }
    if method == FeMethod::ThermoMechanical {
        for (i, rod) in RODS.iter().enumerate() {
            let a = platform_joint(p, rod, pose[0], pose[1], pose[2]);
            let b: Vector2<f64> = carrier_joint(p, rod, placement.carrier[rod.actuator]);
            placement.rod_elongation[i] = p[rod.l] - (a - b).norm();
        }
    }
    placement
}
