//! The time constants a calibration with `thermal` and `thermal_lag` implies: each part's
//! lag α·τ over its coefficient α, with the σ their covariance gives (first order: the ratio's
//! gradient through the effects' covariance). A thermometer 15 minutes behind the rods came
//! out as τ = 886 ± 5 s from α = 11.53 ± 0.01 ppm/K and α·τ = 10219 ± 49 ppm·s/K.

use super::types::Calibration;
use crate::effects::{self, Family};

/// One part's time constant.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TimeConstant {
    /// `tau_rods`.
    pub name: String,
    /// The part (`rods`).
    pub part: String,
    /// Seconds: positive where the thermometer lags the part.
    pub value: f64,
    pub sigma: f64,
}

/// Every part whose α (`thermal`) and α·τ (`thermal_lag`) were both identified.
pub fn time_constants(cal: &Calibration) -> Vec<TimeConstant> {
    let find = |family: &str, name: &str| {
        cal.effects
            .iter()
            .position(|e| effects::family_of(&e.effect) == family && e.name == name && e.identified)
    };
    let mut out = Vec::new();
    for part in ["rods", "frame", "scales"] {
        let (Some(a), Some(l)) = (
            find(Family::Thermal.name(), &format!("alpha_{part}")),
            find(Family::ThermalLag.name(), &format!("lag_{part}")),
        ) else {
            continue;
        };
        let (alpha, lag) = (cal.theta[a], cal.theta[l]);
        if alpha == 0.0 {
            continue;
        }
        let cov = &cal.covariance_theta;
        // τ = l/α: ∂τ/∂l = 1/α, ∂τ/∂α = −l/α²
        let (dl, da) = (1.0 / alpha, -lag / (alpha * alpha));
        let var = dl * dl * cov[(l, l)] + da * da * cov[(a, a)] + 2.0 * dl * da * cov[(a, l)];
        out.push(TimeConstant {
            name: format!("tau_{part}"),
            part: part.to_owned(),
            value: lag / alpha,
            sigma: var.max(0.0).sqrt(),
        });
    }
    out
}
