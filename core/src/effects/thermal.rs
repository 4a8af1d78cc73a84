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
//! `thermal`, τ = lag/α. The rate is the thermometer's along the campaign's time (below).
//! A part that lags its thermometer has a negative τ (to first
//! order in τ; a written `lag(temp_machine, tau)` is exact both ways, docs/effects.md). It
//! is a candidate only beside `thermal` ([`Effect::beside`]).
//!
//! A thermometer's readings hold its noise. The expansion of each reading puts α times it
//! into every row, and a fit sheds it by lowering α (on the twin's lag class a lag and an
//! encoder scale then took the expansion over); a rate fitted over a window misjudges its
//! own error. Each part reading a column therefore reads the column's least-squares fit in
//! smooth terms over the campaign's time, and `thermal_lag` its derivative
//! ([`memory::carried_temperature`], [`memory::carried_rate`]), where that fit holds the
//! readings to their noise; the fit's error is fitted too, as its modes (`temp_error_k`, K,
//! multiplying each part's α; `rate_error_k`, K/s, each part's lag), each anchored near zero
//! by its exact σ. Taken as exact, the rate's error moved the expansion and the lag by up
//! to 12σ on the twin; with both carried, α was within 3σ of the twin's on all 55 parts of
//! the lag class's seeds 1-3 (48 of 54 before). Where the fit does not hold (a temperature
//! set in steps, too few times) or the temperature does not move beyond its noise, the
//! reading and [`memory::rate`] are read as they are, with no modes.

use super::effect::{covariate_column, Bound, Delta, Effect, EffectParam, NotApplicable};
use super::memory::{self, Modes, Timeline};
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
        // most campaigns have one thermometer for all four: its strain (a temperature and a
        // rate are fits over the whole campaign) made once
        let names = ["temp_rods", "temp_frame", "temp_guide1", "temp_guide2"];
        let mut columns: Vec<&str> = Vec::new();
        let read = |part: usize| -> &[&'static str] {
            match part {
                0 => &names[..1],
                1 => &names[1..2],
                _ => &names[2..],
            }
        };
        for &part in &self.parts {
            for name in read(part) {
                let column = Self::column_of(campaign, name);
                if !columns.contains(&column) {
                    columns.push(column);
                }
            }
        }
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
        let mut strains = Vec::new();
        let mut carried = Vec::new();
        for column in &columns {
            let (strain, modes) = self.strain_column(campaign, column)?;
            strains.push(strain);
            let first = params.len();
            params.extend(modes.sigma.iter().enumerate().map(|(k, &s)| {
                EffectParam::new(self.error_name(column, k), self.reads.unit(), s).anchored(s)
            }));
            carried.push(Errors {
                first,
                modes: modes.modes,
            });
        }
        let at = |name: &str| {
            let column = Self::column_of(campaign, name);
            columns.iter().position(|c| *c == column)
        };
        let [rods, frame, guide1, guide2] = names.map(at);
        Ok(Box::new(BoundThermal {
            params,
            carried,
            strains,
            slot: std::array::from_fn(|k| self.parts.iter().position(|&j| j == k)),
            rods,
            frame,
            // carriers 2, 3 ride on guide 1; 1, 4 on guide 2 (spec, frames)
            scales: [guide2, guide1, guide1, guide2],
            lengths: RODS.iter().map(|r| (r.l, p[r.l])).collect(),
            guides: vec![(D1, p[D1]), (D2, p[D2])],
            q: campaign.poses.iter().map(|p| p.q).collect(),
        }))
    }
}

impl Reads {
    fn unit(self) -> &'static str {
        match self {
            Reads::Temperature => "K",
            Reads::Rate => "K/s",
        }
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

    /// (T − T_ref) · 1e-6 per pose from column `name`: the strain per ppm/K; for
    /// `thermal_lag`, dT/dt · 1e-6, the strain per ppm·s/K. Both from the reading's fit over
    /// the campaign's time where it holds the reading to its noise, with the modes of its
    /// error the fit carries ([`memory::carried_temperature`], [`memory::carried_rate`]);
    /// else the reading itself (a temperature) or [`memory::rate`], and no modes.
    fn strain_column(
        &self,
        campaign: &Campaign,
        name: &str,
    ) -> Result<(Vec<f64>, Modes), NotApplicable> {
        let temps = self.temperatures(campaign, name)?;
        let t: Vec<f64> = campaign.poses.iter().map(|p| p.t).collect();
        let line = Timeline::new(&t);
        let (values, modes) = match (self.reads, line) {
            (Reads::Temperature, Ok(line)) => match memory::carried_temperature(&line, &temps) {
                Some(c) => (c.value, c.errors),
                None => (temps, Modes::default()),
            },
            (Reads::Temperature, Err(_)) => (temps, Modes::default()),
            (Reads::Rate, Ok(line)) => match memory::carried_rate(&line, &temps) {
                Some(c) => (c.value, c.errors),
                None => (memory::rate(&line, &temps), Modes::default()),
            },
            (Reads::Rate, Err(e)) => {
                return Err(NotApplicable {
                    effect: self.name.clone(),
                    reason: format!("the thermometers' rate {e} in {}", campaign.source),
                })
            }
        };
        let reference = match self.reads {
            Reads::Temperature => self.reference_c,
            Reads::Rate => 0.0,
        };
        Ok((
            values
                .iter()
                .map(|v| fraction_from_ppm(v - reference))
                .collect(),
            modes,
        ))
    }

    /// The name of the `k`-th mode of the error of column `column`'s temperature (or rate).
    fn error_name(&self, column: &str, k: usize) -> String {
        let what = match self.reads {
            Reads::Temperature => "temp_error",
            Reads::Rate => "rate_error",
        };
        if column == COVARIATE {
            format!("{what}_{k}")
        } else {
            format!("{column}_{what}_{k}")
        }
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

/// One thermometer's error modes in a bound effect: the index of the first in the
/// parameters, and each at every pose.
struct Errors {
    first: usize,
    modes: Vec<Vec<f64>>,
}

struct BoundThermal {
    params: Vec<EffectParam>,
    /// Per column read, its strain per unit of the part's parameter at every pose, and its
    /// error modes.
    strains: Vec<Vec<f64>>,
    carried: Vec<Errors>,
    /// Each part's index in `params` (None: not in the model).
    slot: [Option<usize>; 3],
    /// The column each part reads (an index into `strains`; None: no part of the model
    /// reads it): the rods, the frame, and the scale of each carrier.
    rods: Option<usize>,
    frame: Option<usize>,
    scales: [Option<usize>; 4],
    /// (parameter index, value) of the rod lengths and guide positions.
    lengths: Vec<(usize, f64)>,
    guides: Vec<(usize, f64)>,
    /// Encoder readings per pose (a scale reads short by its expansion).
    q: Vec<[f64; 4]>,
}

impl BoundThermal {
    /// Column `c`'s strain at `pose` with its error modes at `theta`.
    fn strain(&self, c: usize, pose: usize, theta: &[f64]) -> f64 {
        let errors = &self.carried[c];
        self.strains[c][pose]
            + errors
                .modes
                .iter()
                .enumerate()
                .map(|(j, m)| fraction_from_ppm(theta[errors.first + j] * m[pose]))
                .sum::<f64>()
    }

    /// Adds `scale` · (part parameter `k`'s strain of column `c`) at `pose` with `theta` to
    /// the coordinate `at` picks of `value` and of the partials (by the part's parameter and
    /// by the column's modes).
    fn add(
        &self,
        (k, c): (usize, usize),
        (pose, theta): (usize, &[f64]),
        scale: f64,
        (value, partials): (&mut Delta, &mut [Delta]),
        at: impl Fn(&mut Delta) -> &mut f64,
    ) {
        let e = self.strain(c, pose, theta);
        *at(value) += theta[k] * e * scale;
        *at(&mut partials[k]) += e * scale;
        let errors = &self.carried[c];
        for (j, m) in errors.modes.iter().enumerate() {
            *at(&mut partials[errors.first + j]) += fraction_from_ppm(theta[k] * m[pose]) * scale;
        }
    }
}

impl Bound for BoundThermal {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        let here = (pose, theta);
        if let (Some(k), Some(c)) = (self.slot[0], self.rods) {
            for &(i, l) in &self.lengths {
                self.add((k, c), here, l, (&mut *value, &mut *partials), |d| {
                    &mut d.dp[i]
                });
            }
        }
        if let (Some(k), Some(c)) = (self.slot[1], self.frame) {
            for &(i, d) in &self.guides {
                self.add((k, c), here, d, (&mut *value, &mut *partials), |p| {
                    &mut p.dp[i]
                });
            }
        }
        if let Some(k) = self.slot[2] {
            for a in 0..4 {
                if let Some(c) = self.scales[a] {
                    let q = self.q[pose][a];
                    self.add((k, c), here, q, (&mut *value, &mut *partials), |d| {
                        &mut d.dq[a]
                    });
                }
            }
        }
    }
}
