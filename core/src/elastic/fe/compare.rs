//! Every redundant forward model of thesis chapter 5 on the same case: the controller commands
//! all four drives with igm of its (nominal) parameters, the machine has small parameter errors
//! (e.g. 10 µm on l2 or l3, as the thesis's figures 6.18-6.19 and table 6.2), and each model
//! predicts where the TCP ends up and, where it knows stiffness, the drive forces.

use super::error::FeError;
use super::machine::FeStiffness;
use super::methods::{FeMethod, FeModel};
use crate::elastic::baseline;
use crate::elastic::guarded::fegm;
use crate::elastic::spring::{ElasticError, Stiffness, ALL_ACTIVE};
use crate::geometry::{igm, GeometryError};
use crate::params::{Model, Params};

/// The redundant forward models compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum RedundantModel {
    /// Weighted mean of the subsystem fgms (5.1); no stiffness, no forces.
    Statistical,
    /// Least squares over all loop closures (5.2); no stiffness, no forces.
    LeastSquares,
    /// Lumped spring model (5.3; the servo-rate fegm).
    Spring,
    /// Finite elements (5.4), incompatibility as initial strain (5.8, thermo-mechanical).
    FeThermoMechanical,
    /// Finite elements (5.4), incompatibility as drive displacement (5.5,
    /// actuator-displacements).
    FeActuatorDisplacements,
}

impl RedundantModel {
    pub const ALL: [RedundantModel; 5] = [
        RedundantModel::Statistical,
        RedundantModel::LeastSquares,
        RedundantModel::Spring,
        RedundantModel::FeThermoMechanical,
        RedundantModel::FeActuatorDisplacements,
    ];

    /// Position in [`RedundantModel::ALL`].
    pub fn index(self) -> usize {
        match self {
            RedundantModel::Statistical => 0,
            RedundantModel::LeastSquares => 1,
            RedundantModel::Spring => 2,
            RedundantModel::FeThermoMechanical => 3,
            RedundantModel::FeActuatorDisplacements => 4,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            RedundantModel::Statistical => "statistical (5.1)",
            RedundantModel::LeastSquares => "least squares (5.2)",
            RedundantModel::Spring => "spring fegm (5.3)",
            RedundantModel::FeThermoMechanical => "FE thermo-mechanical",
            RedundantModel::FeActuatorDisplacements => "FE actuator-displacements",
        }
    }
}

/// One model's answer on a case.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MethodResult {
    pub model: RedundantModel,
    /// TCP error: predicted pose − commanded pose, x, y (mm) and ψ (rad).
    pub tcp_error: [f64; 3],
    /// Drive forces f1..f4, N (models with stiffness only).
    pub drive_force: Option<[f64; 4]>,
}

/// All models on one case.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Comparison {
    /// Commanded TCP, mm.
    pub x: f64,
    pub y: f64,
    /// Parameter errors of the machine: (parameter index, error in mm or rad).
    pub errors: Vec<(usize, f64)>,
    /// Commanded actuator positions (igm of the nominal parameters), mm.
    pub q: [f64; 4],
    /// In the order of [`RedundantModel::ALL`].
    pub results: [MethodResult; 5],
}

impl Comparison {
    pub fn result(&self, model: RedundantModel) -> &MethodResult {
        &self.results[model.index()]
    }
}

/// A model that failed on a case.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ComparisonError {
    #[error("commanded pose: {0}")]
    Command(#[from] GeometryError),
    #[error("baseline or spring model: {0}")]
    Lumped(#[from] ElasticError),
    #[error("finite-element model: {0}")]
    Fe(#[from] FeError),
}

/// Runs every model on the case: drives at igm(`nominal`, x, y), machine = `nominal` +
/// `errors`, all four drives active.
pub fn compare_methods(
    nominal: &Params,
    spring: &Stiffness,
    fe: &FeStiffness,
    x: f64,
    y: f64,
    errors: &[(usize, f64)],
) -> Result<Comparison, ComparisonError> {
    let command = igm(nominal, Model::M29, x, y)?;
    let q = command.q();
    let mut machine = *nominal;
    for &(i, d) in errors {
        machine[i] += d;
    }
    let target = [x, y, command.psi()];
    let err = |pose: [f64; 3]| [0, 1, 2].map(|r| pose[r] - target[r]);
    let st = baseline::statistical(&machine, Model::M29, q)?;
    let ls = baseline::least_squares(&machine, q)?;
    let sp = fegm(&machine, spring, q, ALL_ACTIVE)?;
    let mut model = FeModel::new(*fe)?;
    let th = model.solve(&machine, q, ALL_ACTIVE, FeMethod::ThermoMechanical)?;
    let ad = model.solve(&machine, q, ALL_ACTIVE, FeMethod::ActuatorDisplacements)?;
    let results = [
        MethodResult {
            model: RedundantModel::Statistical,
            tcp_error: err([st.x, st.y, st.psi]),
            drive_force: None,
        },
        MethodResult {
            model: RedundantModel::LeastSquares,
            tcp_error: err([ls.x, ls.y, ls.psi]),
            drive_force: None,
        },
        MethodResult {
            model: RedundantModel::Spring,
            tcp_error: err([sp.x, sp.y, sp.psi]),
            drive_force: Some(sp.drive_force),
        },
        MethodResult {
            model: RedundantModel::FeThermoMechanical,
            tcp_error: err([th.x, th.y, th.psi]),
            drive_force: Some(th.drive_force),
        },
        MethodResult {
            model: RedundantModel::FeActuatorDisplacements,
            tcp_error: err([ad.x, ad.y, ad.psi]),
            drive_force: Some(ad.drive_force),
        },
    ];
    Ok(Comparison {
        x,
        y,
        errors: errors.to_vec(),
        q,
        results,
    })
}
