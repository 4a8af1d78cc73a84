//! `thermal`: thermal expansion, as the three parts of a machine that expand on their own:
//!
//! - `alpha_rods`: the rod lengths l1..l5 (temperature `temp_rods`);
//! - `alpha_frame`: the frame that holds the guides apart, d1 and d2 (`temp_frame`);
//! - `alpha_scales`: the linear scales of the carriers, q grows with the reading (guide 1,
//!   carriers 2 and 3: `temp_guide1`; guide 2, carriers 1 and 4: `temp_guide2`).
//!
//! Each part reads its own temperature column when the campaign has one and `temp_machine`
//! otherwise; each has its own coefficient (ppm/K), strain α · (T − T_ref) with the reference
//! temperature an input ([`Thermal::reference_c`], the spec's 20 °C by default). A machine
//! whose rods alone expand gets `alpha_rods` and two parts the data do not support: the
//! diagnosis keeps only the parts whose estimate stands out of its uncertainty. A geometric
//! calibration at one temperature absorbs the mean; what it cannot absorb is the drift of the
//! temperatures during the campaign.

use super::effect::{covariate_column, Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::Campaign;
use crate::params::{Params, D1, D2, RODS};

/// The temperature every part falls back to.
pub const COVARIATE: &str = "temp_machine";
/// The spec's reference temperature, °C.
pub const REFERENCE_C: f64 = 20.0;

/// See the module documentation.
pub struct Thermal {
    /// Temperature at which the nominal geometry holds, °C.
    pub reference_c: f64,
}

impl Default for Thermal {
    fn default() -> Self {
        Thermal {
            reference_c: REFERENCE_C,
        }
    }
}

/// The three parts, in parameter order.
const PARTS: [(&str, &str); 3] = [
    ("alpha_rods", "temp_rods"),
    ("alpha_frame", "temp_frame"),
    ("alpha_scales", ""),
];

impl Effect for Thermal {
    fn name(&self) -> &'static str {
        "thermal"
    }
    fn summary(&self) -> &'static str {
        "thermal expansion of rods, frame (guide positions) and scales, each with its own \
         coefficient and temperature"
    }
    fn covariates(&self) -> &'static [&'static str] {
        &[COVARIATE]
    }
    fn bind(&self, campaign: &Campaign, p: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        let rods = self.strain_column(campaign, "temp_rods")?;
        let frame = self.strain_column(campaign, "temp_frame")?;
        let guide1 = self.strain_column(campaign, "temp_guide1")?;
        let guide2 = self.strain_column(campaign, "temp_guide2")?;
        let params = PARTS
            .iter()
            .map(|(name, _)| EffectParam {
                name: (*name).to_owned(),
                unit: "ppm/K".into(),
                prior: 10.0,
            })
            .collect();
        Ok(Box::new(BoundThermal {
            params,
            rods,
            frame,
            // carriers 2, 3 ride on guide 1; 1, 4 on guide 2 (spec, frames)
            scales: (0..campaign.poses.len())
                .map(|i| [guide2[i], guide1[i], guide1[i], guide2[i]])
                .collect(),
            lengths: RODS.iter().map(|r| (r.l, p[r.l])).collect(),
            guides: vec![(D1, p[D1]), (D2, p[D2])],
            q: campaign.poses.iter().map(|p| p.q).collect(),
        }))
    }
}

impl Thermal {
    /// (T − T_ref) · 1e-6 per pose from column `name`, or `temp_machine` without it: the
    /// strain per ppm/K.
    fn strain_column(&self, campaign: &Campaign, name: &str) -> Result<Vec<f64>, NotApplicable> {
        let column = if campaign.covariate_index(name).is_some() {
            name
        } else {
            COVARIATE
        };
        let temps = covariate_column(campaign, "thermal", column)?;
        temps
            .iter()
            .enumerate()
            .map(|(i, t)| {
                t.map(|t| (t - self.reference_c) * 1e-6)
                    .ok_or_else(|| NotApplicable {
                        effect: "thermal".into(),
                        reason: format!(
                            "{}:{}: no {column} value",
                            campaign.source, campaign.poses[i].line
                        ),
                    })
            })
            .collect()
    }
}

struct BoundThermal {
    params: Vec<EffectParam>,
    /// Strain per ppm/K of each part, per pose.
    rods: Vec<f64>,
    frame: Vec<f64>,
    scales: Vec<[f64; 4]>,
    /// (parameter index, value) of the rod lengths and guide positions.
    lengths: Vec<(usize, f64)>,
    guides: Vec<(usize, f64)>,
    /// Encoder readings per pose (a scale reads short by its expansion).
    q: Vec<[f64; 4]>,
}

impl Bound for BoundThermal {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        let (er, ef) = (self.rods[pose], self.frame[pose]);
        for &(i, l) in &self.lengths {
            value.dp[i] += theta[0] * er * l;
            partials[0].dp[i] += er * l;
        }
        for &(i, d) in &self.guides {
            value.dp[i] += theta[1] * ef * d;
            partials[1].dp[i] += ef * d;
        }
        for a in 0..4 {
            let e = self.scales[pose][a] * self.q[pose][a];
            value.dq[a] += theta[2] * e;
            partials[2].dq[a] += e;
        }
    }
}
