//! What a plan starts from (a campaign calibrated, with the noise it showed) and the rows
//! a plan's poses give, as the calibration weighs them. Read by the planner's files.

use super::types::{PlanError, Unknowns};
use crate::analysis;
use crate::campaign::Campaign;
use crate::design::PlannedPose;
use crate::effects::Corrections;
use crate::noise::NoiseModel;
use crate::obs::{self, Residual, Step};
use crate::params::{Model, Params};
use nalgebra::DMatrix;

/// What a plan starts from: a campaign calibrated at `params` with the noise it showed.
#[derive(Clone, Copy, Debug)]
pub struct Start<'a> {
    pub campaign: &'a Campaign,
    pub params: &'a Params,
    pub model: Model,
    pub noise: &'a NoiseModel,
}

impl Start<'_> {
    /// The campaign's information on `unknowns` (its rows at the calibrated parameters).
    pub fn information(&self, unknowns: &Unknowns) -> Result<DMatrix<f64>, PlanError> {
        let rows = obs::residuals_with(
            self.campaign,
            self.params,
            self.model,
            Step::Direct,
            self.params,
            &Corrections::default(),
            self.noise,
        )?;
        Ok(unknowns.information(&rows))
    }
}

/// The calibration rows of a design on a machine with parameters `p` (measured values
/// consistent with `p`: only the Jacobian and σ matter), weighted with `noise`, as the
/// calibration writes them (decorrelated), direct rows only.
pub fn design_rows(
    design: &[PlannedPose],
    p: &Params,
    model: Model,
    noise: &NoiseModel,
) -> Result<Vec<Residual>, PlanError> {
    let c = analysis::nominal_campaign(design, p, model)?;
    Ok(obs::residuals_with(
        &c,
        p,
        model,
        Step::Direct,
        p,
        &Corrections::default(),
        noise,
    )?)
}
