//! `thermal`: thermal expansion, as the three parts of a machine that expand on their own:
//!
//! - `alpha_rods`: the rod lengths l1..l5 (temperature `temp_rods`);
//! - `alpha_frame`: the frame that holds the guides apart, d1 and d2 (`temp_frame`);
//! - `alpha_scales`: the linear scales of the carriers, q grows with the reading (guide 1,
//!   carriers 2 and 3: `temp_guide1`; guide 2, carriers 1 and 4: `temp_guide2`).
//!
//! Each part reads its own temperature column when the campaign has one and `temp_machine`
//! otherwise; each has its own coefficient (ppm/K), strain α · (T − T_ref) with the reference
//! temperature an input ([`Thermal::reference_c`], the spec's 20 °C by default). A geometric
//! calibration at one temperature absorbs the mean; what it cannot absorb is the drift of the
//! temperatures during the campaign.
//!
//! The three parts form a family ([`Effect::parts`]): `thermal` names it whole and leaves
//! the parts to the data (a campaign of a tracker and self-calibration cannot tell the rods'
//! expansion from the frame's and the scales', and the three fitted together come out as
//! numbers no material has), `thermal:rods` or `thermal:rods+scales` pins them.

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
    /// The parts in the model (indices into [`PARTS`], ascending); all three where the
    /// family is named whole.
    parts: Vec<usize>,
    /// Whether the family was named whole (`thermal`), its parts left to the data.
    open: bool,
    /// `thermal`, or `thermal:rods+frame` with pinned parts.
    name: String,
}

impl Default for Thermal {
    fn default() -> Self {
        Thermal {
            reference_c: REFERENCE_C,
            parts: (0..PARTS.len()).collect(),
            open: true,
            name: NAME.to_owned(),
        }
    }
}

const NAME: &str = "thermal";

/// The three parts: name, parameter, and the temperature column each reads when the campaign
/// has it (the scales read their guide's).
const PARTS: [(&str, &str, &str); 3] = [
    ("rods", "alpha_rods", "temp_rods"),
    ("frame", "alpha_frame", "temp_frame"),
    ("scales", "alpha_scales", ""),
];

/// Expansion coefficients real machine materials have, ppm/K (CFRP a little below zero,
/// invar about 1, steel and cast iron 10-13, aluminium 23), with room for a part whose
/// temperature runs ahead of the thermometer it is read from.
const ALPHA_RANGE_PPM_PER_K: (f64, f64) = (-5.0, 40.0);

impl Effect for Thermal {
    fn name(&self) -> &str {
        &self.name
    }
    fn summary(&self) -> &'static str {
        "thermal expansion of rods, frame (guide positions) and scales, each with its own \
         coefficient and temperature"
    }
    fn covariates(&self) -> &'static [&'static str] {
        &[COVARIATE]
    }
    fn parts(&self) -> &'static [&'static str] {
        &["rods", "frame", "scales"]
    }
    fn with_parts(&self, parts: &[usize]) -> Option<Box<dyn Effect>> {
        let mut parts: Vec<usize> = parts.iter().copied().filter(|&k| k < PARTS.len()).collect();
        parts.sort_unstable();
        parts.dedup();
        if parts.is_empty() {
            return None;
        }
        let names: Vec<&str> = parts.iter().map(|&k| PARTS[k].0).collect();
        Some(Box::new(Thermal {
            reference_c: self.reference_c,
            name: format!("{NAME}:{}", names.join("+")),
            parts,
            open: false,
        }))
    }
    fn open_family(&self) -> bool {
        self.open
    }
    fn bind(&self, campaign: &Campaign, p: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        let rods = self.strain_column(campaign, "temp_rods")?;
        let frame = self.strain_column(campaign, "temp_frame")?;
        let guide1 = self.strain_column(campaign, "temp_guide1")?;
        let guide2 = self.strain_column(campaign, "temp_guide2")?;
        let params = self
            .parts
            .iter()
            .map(|&k| {
                let (lo, hi) = ALPHA_RANGE_PPM_PER_K;
                EffectParam::new(PARTS[k].1, "ppm/K", 10.0).within(lo, hi)
            })
            .collect();
        Ok(Box::new(BoundThermal {
            params,
            slot: std::array::from_fn(|k| self.parts.iter().position(|&j| j == k)),
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
    /// Each part's index in `params` (None: not in the model).
    slot: [Option<usize>; 3],
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
        if let Some(k) = self.slot[0] {
            for &(i, l) in &self.lengths {
                value.dp[i] += theta[k] * er * l;
                partials[k].dp[i] += er * l;
            }
        }
        if let Some(k) = self.slot[1] {
            for &(i, d) in &self.guides {
                value.dp[i] += theta[k] * ef * d;
                partials[k].dp[i] += ef * d;
            }
        }
        if let Some(k) = self.slot[2] {
            for a in 0..4 {
                let e = self.scales[pose][a] * self.q[pose][a];
                value.dq[a] += theta[k] * e;
                partials[k].dq[a] += e;
            }
        }
    }
}
