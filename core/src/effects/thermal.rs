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
//!
//! `thermal_lag` is the same three parts read through their thermometers' rate: a
//! thermometer that lags the part it stands for by a first-order time constant τ reads
//! `T_part − τ · dT/dt`, so the part's strain is `α · (T − T_ref) + α·τ · dT/dt`. Its
//! parameters are the products `lag_PART` = α·τ (ppm·s/K), linear in the rows like the
//! coefficients (a time constant of its own would move nothing while α is zero); beside
//! `thermal`, τ = lag/α. The rate is the thermometer's along the campaign's time
//! ([`super::memory::rate`]). A part that lags its thermometer has a negative τ (to first
//! order in τ; a written `lag(temp_machine, tau)` is exact both ways, docs/effects.md). It
//! is a candidate only beside `thermal` ([`Effect::beside`]).
//!
//! The rate is a fit over minutes of noisy readings, and the self-calibration resolves a
//! part's temperature finer than that rate times a lag gives it: `thermal_lag` fits the
//! rate's error too, as smooth terms in time (`rate_error_k`, K/s, multiplying each part's
//! lag), each anchored near zero by the rate's own estimated error (`Wander`). Taken as
//! exact, the rate's error moved the expansion and the lag by up to 12σ on the twin.

use super::effect::{covariate_column, Bound, Delta, Effect, EffectParam, NotApplicable};
use super::memory::{self, Timeline};
use crate::campaign::Campaign;
use crate::params::{Params, D1, D2, RODS};
use crate::units::fraction_from_ppm;

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
    /// What the strain follows: the temperature, or its rate (`thermal_lag`).
    reads: Reads,
}

/// What a [`Thermal`]'s strain follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reads {
    /// α · (T − T_ref): `thermal`.
    Temperature,
    /// α·τ · dT/dt: `thermal_lag`.
    Rate,
}

impl Default for Thermal {
    fn default() -> Self {
        Thermal {
            reference_c: REFERENCE_C,
            parts: (0..PARTS.len()).collect(),
            open: true,
            name: NAME.to_owned(),
            reads: Reads::Temperature,
        }
    }
}

impl Thermal {
    /// `thermal_lag`, its parts left to the data.
    pub fn lag() -> Thermal {
        Thermal {
            name: LAG_NAME.to_owned(),
            reads: Reads::Rate,
            ..Thermal::default()
        }
    }

    fn family(&self) -> &'static str {
        match self.reads {
            Reads::Temperature => NAME,
            Reads::Rate => LAG_NAME,
        }
    }
}

const NAME: &str = super::family::Family::Thermal.name();
const LAG_NAME: &str = super::family::Family::ThermalLag.name();

/// The lag's product α·τ: its scale in the fit (10 ppm/K for ten minutes), and what real
/// coefficients and lags of minutes to four hours make, either way.
const LAG_PRIOR: f64 = 6000.0;
const LAG_RANGE: f64 = 40.0 * 4.0 * 3600.0;

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
        match self.reads {
            Reads::Temperature => {
                "thermal expansion of rods, frame (guide positions) and scales, each with its \
                 own coefficient and temperature"
            }
            Reads::Rate => {
                "thermometers that lag (or lead) the rods, frame and scales they stand for: \
                 the expansion of each part's temperature rate times its coefficient and lag \
                 (beside thermal)"
            }
        }
    }
    fn has_memory(&self) -> bool {
        self.reads == Reads::Rate
    }
    fn beside(&self) -> Option<&'static str> {
        (self.reads == Reads::Rate).then_some(NAME)
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
            name: format!("{}:{}", self.family(), names.join("+")),
            parts,
            open: false,
            reads: self.reads,
        }))
    }
    fn open_family(&self) -> bool {
        self.open
    }
    fn bind(&self, campaign: &Campaign, p: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        // most campaigns have one thermometer for all four: its strain (a rate is a fit over
        // the whole campaign) made once
        let mut made: Vec<(&str, Vec<f64>)> = Vec::new();
        let mut strain = |name: &'static str| -> Result<Vec<f64>, NotApplicable> {
            let column = Self::column_of(campaign, name);
            if let Some((_, s)) = made.iter().find(|(c, _)| *c == column) {
                return Ok(s.clone());
            }
            let s = self.strain_column(campaign, column)?;
            made.push((column, s.clone()));
            Ok(s)
        };
        let rods = strain("temp_rods")?;
        let frame = strain("temp_frame")?;
        let guide1 = strain("temp_guide1")?;
        let guide2 = strain("temp_guide2")?;
        let wander = match self.reads {
            Reads::Rate => self.wander(campaign)?,
            Reads::Temperature => Wander::default(),
        };
        let mut params: Vec<EffectParam> = self
            .parts
            .iter()
            .map(|&k| match self.reads {
                Reads::Temperature => {
                    let (lo, hi) = ALPHA_RANGE_PPM_PER_K;
                    EffectParam::new(PARTS[k].1, "ppm/K", 10.0).within(lo, hi)
                }
                Reads::Rate => {
                    let name = PARTS[k].1.replace("alpha", "lag");
                    EffectParam::new(name, "ppm·s/K", LAG_PRIOR).within(-LAG_RANGE, LAG_RANGE)
                }
            })
            .collect();
        let first_wander = params.len();
        params.extend(
            wander
                .sigma
                .iter()
                .enumerate()
                .map(|(k, &s)| EffectParam::new(format!("rate_error_{k}"), "K/s", s).anchored(s)),
        );
        Ok(Box::new(BoundThermal {
            params,
            first_wander,
            wander: wander.basis,
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
    /// The column part `name` reads: its own where the campaign has it, else `temp_machine`.
    fn column_of<'a>(campaign: &Campaign, name: &'a str) -> &'a str {
        if campaign.covariate_index(name).is_some() {
            name
        } else {
            COVARIATE
        }
    }

    /// (T − T_ref) · 1e-6 per pose from column `name`, or `temp_machine` without it: the
    /// strain per ppm/K; for `thermal_lag`, dT/dt · 1e-6, the strain per ppm·s/K.
    fn strain_column(&self, campaign: &Campaign, name: &str) -> Result<Vec<f64>, NotApplicable> {
        let temps = self.temperatures(campaign, name)?;
        if self.reads == Reads::Temperature {
            return Ok(temps
                .iter()
                .map(|t| fraction_from_ppm(t - self.reference_c))
                .collect());
        }
        let t: Vec<f64> = campaign.poses.iter().map(|p| p.t).collect();
        let line = Timeline::new(&t).map_err(|e| NotApplicable {
            effect: self.name.clone(),
            reason: format!("the thermometers' rate {e} in {}", campaign.source),
        })?;
        Ok(memory::rate(&line, &temps)
            .iter()
            .map(|r| fraction_from_ppm(*r))
            .collect())
    }

    /// The temperature part `name` reads at every pose (`temp_machine` where the campaign
    /// has no column `name`), °C.
    fn temperatures(&self, campaign: &Campaign, name: &str) -> Result<Vec<f64>, NotApplicable> {
        let column = Self::column_of(campaign, name);
        let temps = covariate_column(campaign, "thermal", column)?;
        temps
            .iter()
            .enumerate()
            .map(|(i, t)| {
                t.ok_or_else(|| NotApplicable {
                    effect: self.family().into(),
                    reason: format!(
                        "{}:{}: no {column} value",
                        campaign.source, campaign.poses[i].line
                    ),
                })
            })
            .collect()
    }
}

/// A lagging thermometer's rate error as a smooth function of the campaign's time: Legendre
/// polynomials over the campaign, two per half-width of the rate's window plus one, each
/// with the σ that spreads the rate's estimated error evenly over them.
#[derive(Default)]
struct Wander {
    /// Per term, its value at each pose.
    basis: Vec<Vec<f64>>,
    sigma: Vec<f64>,
}

impl Thermal {
    fn wander(&self, campaign: &Campaign) -> Result<Wander, NotApplicable> {
        let temps = self.temperatures(campaign, COVARIATE)?;
        let t: Vec<f64> = campaign.poses.iter().map(|p| p.t).collect();
        let Ok(line) = Timeline::new(&t) else {
            return Ok(Wander::default());
        };
        let (_, half, error) = memory::rate_fit(&line, &temps);
        let Some(basis) = memory::smooth_terms(&t, half).filter(|_| error > 0.0) else {
            return Ok(Wander::default());
        };
        let n = basis.len();
        Ok(Wander {
            basis,
            sigma: {
                // the rate's error is the readings' noise differentiated: its power grows
                // with the square of the frequency, a term's with (k + ½)², and the terms
                // together make the rate's estimated error (a Legendre term's mean square
                // over the campaign is 1/(2k + 1))
                let power = |k: usize| (k as f64 + 0.5).powi(2);
                let total: f64 = (0..n).map(power).sum();
                (0..n)
                    .map(|k| error * (power(k) * (2 * k + 1) as f64 / total).sqrt())
                    .collect()
            },
        })
    }
}

struct BoundThermal {
    params: Vec<EffectParam>,
    /// The index of the first rate-error term in `params`, and each term per pose.
    first_wander: usize,
    wander: Vec<Vec<f64>>,
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
        // the rate's error at this pose (strain per ppm·s/K), and the terms it is made of
        let terms = self.first_wander..self.first_wander + self.wander.len();
        let err: f64 = terms
            .clone()
            .zip(&self.wander)
            .map(|(j, b)| fraction_from_ppm(theta[j] * b[pose]))
            .sum::<f64>();
        let (er, ef) = (self.rods[pose] + err, self.frame[pose] + err);
        if let Some(k) = self.slot[0] {
            for &(i, l) in &self.lengths {
                value.dp[i] += theta[k] * er * l;
                partials[k].dp[i] += er * l;
                for (j, b) in terms.clone().zip(&self.wander) {
                    partials[j].dp[i] += fraction_from_ppm(theta[k] * b[pose]) * l;
                }
            }
        }
        if let Some(k) = self.slot[1] {
            for &(i, d) in &self.guides {
                value.dp[i] += theta[k] * ef * d;
                partials[k].dp[i] += ef * d;
                for (j, b) in terms.clone().zip(&self.wander) {
                    partials[j].dp[i] += fraction_from_ppm(theta[k] * b[pose]) * d;
                }
            }
        }
        if let Some(k) = self.slot[2] {
            for a in 0..4 {
                let e = (self.scales[pose][a] + err) * self.q[pose][a];
                value.dq[a] += theta[k] * e;
                partials[k].dq[a] += e;
                for (j, b) in terms.clone().zip(&self.wander) {
                    partials[j].dq[a] += fraction_from_ppm(theta[k] * b[pose]) * self.q[pose][a];
                }
            }
        }
    }
}
