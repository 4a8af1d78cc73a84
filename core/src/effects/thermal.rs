//! `thermal`: thermal expansion of rods, guide positions and linear scales with the machine
//! temperature (covariate `temp_machine`, °C). One parameter, the effective expansion
//! coefficient α (ppm/K): every rod length l, the guide positions d1, d2 and every carrier
//! position q grow by α · (T − 20 °C). A geometric calibration at one temperature absorbs the
//! mean; what it cannot absorb is the drift of the temperature during the campaign.

use super::{covariate_column, Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::Campaign;
use crate::params::{Params, D1, D2, RODS};
use crate::twin::effects::REFERENCE_TEMP_C;

/// Covariate the effect reads.
pub const COVARIATE: &str = "temp_machine";

/// See the module documentation.
pub struct Thermal;

impl Effect for Thermal {
    fn name(&self) -> &'static str {
        "thermal"
    }
    fn summary(&self) -> &'static str {
        "thermal expansion of rods, guides and scales with temp_machine"
    }
    fn covariates(&self) -> &'static [&'static str] {
        &[COVARIATE]
    }
    fn bind(&self, campaign: &Campaign, p: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        let temps = covariate_column(campaign, self.name(), COVARIATE)?;
        let dt: Vec<f64> = temps
            .iter()
            .enumerate()
            .map(|(i, t)| {
                t.map(|t| t - REFERENCE_TEMP_C)
                    .ok_or_else(|| NotApplicable {
                        effect: "thermal",
                        reason: format!(
                            "{}:{}: no {COVARIATE} value",
                            campaign.source, campaign.poses[i].line
                        ),
                    })
            })
            .collect::<Result<_, _>>()?;
        let mut lengths: Vec<(usize, f64)> = RODS.iter().map(|r| (r.l, p[r.l])).collect();
        lengths.push((D1, p[D1]));
        lengths.push((D2, p[D2]));
        let q = campaign.poses.iter().map(|p| p.q).collect();
        Ok(Box::new(BoundThermal {
            params: vec![EffectParam {
                name: "alpha".to_owned(),
                unit: "ppm/K",
                prior: 10.0,
            }],
            dt,
            lengths,
            q,
        }))
    }
}

struct BoundThermal {
    params: Vec<EffectParam>,
    /// T − 20 °C per pose.
    dt: Vec<f64>,
    /// (parameter index, value) of the lengths that expand.
    lengths: Vec<(usize, f64)>,
    /// Encoder readings per pose (the scales expand with the guides).
    q: Vec<[f64; 4]>,
}

impl Bound for BoundThermal {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        // strain per ppm/K at this pose
        let e = self.dt[pose] * 1e-6;
        for &(i, l) in &self.lengths {
            value.dp[i] += theta[0] * e * l;
            partials[0].dp[i] += e * l;
        }
        for a in 0..4 {
            value.dq[a] += theta[0] * e * self.q[pose][a];
            partials[0].dq[a] += e * self.q[pose][a];
        }
    }
}
