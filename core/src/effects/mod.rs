//! Physical effects as plug-ins of the model: what the geometric model of chapter 4 does not
//! describe (an imperfect parallel-holder, elastic preload, thermal expansion, an encoder scale
//! error, a bowed guide, a rotated instrument).
//!
//! An [`Effect`] is bound to a campaign ([`Effect::bind`]): it reads the covariates it needs
//! (temperatures, drive forces, setups) once, declares its parameters (name, unit, prior
//! magnitude) and then, for any values θ of them, says how each pose's model inputs change:
//!
//! - `dp`: the 29 geometric parameters at this pose (a temperature-dependent rod length, a
//!   carrier joint offset that follows a bowed guide, a rod stretched by its force);
//! - `dq`: carrier position minus encoder reading (a scale error);
//! - `dm`: the true minus the recorded (x, y) of the instrument (a rotated instrument frame);
//! - `dpsi`: the true minus the recorded platform angle (an angle interferometer's error).
//!
//! with their derivatives ∂/∂θ. The model values (`obs`) are evaluated at the corrected inputs
//! and carry their own sensitivities to p, q and m, so a Jacobian column of θ is the chain rule
//! `∂value/∂p · ∂dp/∂θ + ∂value/∂q · ∂dq/∂θ + ∂value/∂m · ∂dm/∂θ`, computed in one place
//! ([`Delta::chain`]) for every effect: adding an effect never touches the calibration.
//!
//! Adding an effect is one new file with a type implementing [`Effect`] and one line in
//! [`library`] (docs/effects.md walks through one).

mod effect;
mod encoder_scale;
pub mod expr;
mod family;
mod guide_straightness;
mod instrument_alignment;
pub mod live;
pub mod memory;
mod packed;
mod parallelogram;
mod preload_elastic;
pub mod stiffness_factor;
mod thermal;
pub mod written;

pub use effect::{Bound, Delta, Effect, EffectParam, InputSensitivity, NotApplicable, Slope};
pub use encoder_scale::EncoderScale;
pub use family::{family_of, held_parts, pinned_parts, Family};
pub use guide_straightness::GuideStraightness;
pub use instrument_alignment::InstrumentAlignment;
pub use live::{LiveEffects, LiveError, LiveState};
pub use parallelogram::Parallelogram;
pub use preload_elastic::PreloadElastic;
pub use stiffness_factor::StiffnessFactor;
pub use thermal::Thermal;
pub use written::Written;

use std::sync::Arc;

use crate::campaign::Campaign;
use crate::params::Params;

pub use crate::params::Row;

/// The effects the diagnosis knows, in the order it tries them.
pub fn library() -> Vec<Box<dyn Effect>> {
    vec![
        Box::new(Parallelogram),
        Box::new(PreloadElastic::default()),
        Box::new(Thermal::default()),
        Box::new(Thermal::lag()),
        Box::new(EncoderScale),
        Box::new(GuideStraightness),
        Box::new(InstrumentAlignment),
    ]
}

/// Every effect a calibration can be asked for: the [`library`] and the stiffness factor of
/// the drive-force rows ([`StiffnessFactor`]), which the diagnosis does not try (it changes
/// nothing but the forces, and the forces scale with it exactly as with the geometry's
/// distance from the controller's: see docs/calibration.md).
pub fn all() -> Vec<Box<dyn Effect>> {
    let mut out = library();
    out.push(Box::new(StiffnessFactor));
    out
}

/// Names of the effects of [`all`].
pub fn names() -> Vec<String> {
    all().iter().map(|e| e.name().to_owned()).collect()
}

/// The effect called `name` (of [`all`]), a family's parts `family:part+part`
/// (`thermal:rods`, `thermal:rods+scales`), or an effect's refinement
/// (`preload_elastic:rod2`, [`Effect::refinements`]).
pub fn by_name(name: &str) -> Result<Box<dyn Effect>, UnknownEffect> {
    let unknown = |known: String| UnknownEffect {
        name: name.to_owned(),
        known,
    };
    let (family, parts) = match name.trim().split_once(':') {
        Some((f, p)) => (f.trim(), Some(p)),
        None => (name.trim(), None),
    };
    let effect = all()
        .into_iter()
        .find(|e| e.name() == family)
        .ok_or_else(|| unknown(names().join(", ")))?;
    let Some(parts) = parts else {
        return Ok(effect);
    };
    let refinements = effect.refinements();
    if !refinements.is_empty() {
        let wanted = format!("{family}:{}", parts.trim());
        let names: Vec<String> = refinements.iter().map(|r| r.name().to_owned()).collect();
        return refinements
            .into_iter()
            .find(|r| r.name() == wanted)
            .ok_or_else(|| unknown(names.join(", ")));
    }
    let known = effect.parts();
    let with = |list: &str| {
        format!(
            "{family}:PART+PART with parts {list}",
            list = if list.is_empty() { "(none)" } else { list }
        )
    };
    let indices = parts
        .split('+')
        .map(|p| known.iter().position(|k| *k == p.trim()))
        .collect::<Option<Vec<usize>>>()
        .ok_or_else(|| unknown(with(&known.join(", "))))?;
    effect
        .with_parts(&indices)
        .ok_or_else(|| unknown(with(&known.join(", "))))
}

/// A list `a,b,c` of effect names.
pub fn parse_list(list: &str) -> Result<Vec<Box<dyn Effect>>, UnknownEffect> {
    list.split(',')
        .filter(|s| !s.trim().is_empty())
        .map(by_name)
        .collect()
}

/// An effect name the library does not have.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown effect {name:?}, expected one of {known}")]
pub struct UnknownEffect {
    pub name: String,
    pub known: String,
}

/// The corrections of every pose of a campaign for given effect parameters: per pose the
/// change and its derivatives per effect parameter (all effects' parameters in one vector, see
/// [`EffectSet::layout`]), only those the effects may make non-zero there
/// ([`Bound::touched`]): an instrument's alignment angles are zero away from their setup, and
/// dense partials of 51 setups' angles were 15 MB per evaluation of a 1,000-pose campaign.
#[derive(Clone, Debug, Default)]
pub struct Corrections {
    /// Per pose (its index), the change, packed as the partials are. Empty when there is
    /// no effect.
    values: packed::Packed,
    /// Per pose, where its partials start in `partials` (one more entry: the end).
    starts: Vec<usize>,
    /// The partials of every pose in pose order: parameter index (ascending within a pose)
    /// and ∂/∂θ of the change, packed ([`packed::Packed`]: a few of its 37 fields each).
    partials: packed::Packed,
    pub n_params: usize,
    /// Where the changes read the geometry ([`Bound::correct_at`]): the parameters they
    /// were made at, per pose where its slopes start in `slopes` (one more entry: the end),
    /// and the slopes ([`Slope`]). None where no change reads it.
    geometry: Option<GeometrySlopes>,
}

/// A partial of a binding that reads no geometry, chained through the slopes of one pose's
/// bindings that read it: its change of the pose's inputs moves the pose they read.
fn chain_through(d: &mut Delta, slopes: &[Slope]) {
    let before = *d;
    for g in slopes {
        d.dp[g.param] += g.of(&before);
    }
}

/// The slopes of corrections that read the geometry (see [`Corrections`]).
#[derive(Clone, Debug)]
struct GeometrySlopes {
    at: Params,
    starts: Vec<usize>,
    slopes: Vec<Slope>,
}

impl Corrections {
    /// The same change `value` and partials `partials` (one per parameter) at each of
    /// `n_poses` poses.
    pub fn uniform(n_poses: usize, value: Delta, partials: &[Delta]) -> Corrections {
        let mut out = Corrections {
            n_params: partials.len(),
            ..Corrections::default()
        };
        out.starts.push(0);
        for _ in 0..n_poses {
            out.values.push(out.values.len(), &value);
            for (k, d) in partials.iter().enumerate() {
                out.partials.push(k, d);
            }
            out.starts.push(out.partials.len());
        }
        out
    }

    /// Whether no pose is changed: no effect bound (every [`Corrections::delta`] zero).
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The change at pose `i` (none without effects).
    ///
    /// # Panics
    /// If effects are bound and `i` is not a pose of the campaign they were bound to: a
    /// correction of another campaign's pose would be a wrong number, not a missing one.
    pub fn delta(&self, i: usize) -> Delta {
        if self.values.is_empty() {
            return Delta::default();
        }
        match (i < self.values.len()).then(|| self.values.get(i).1) {
            Some(d) => d,
            None => panic!(
                "effect corrections of {} poses asked for pose {i}: bound to another campaign",
                self.values.len()
            ),
        }
    }

    /// The partials of pose `i` that may be non-zero (none past the campaign's poses).
    fn partials_of(&self, i: usize) -> impl Iterator<Item = (usize, Delta)> + '_ {
        let range = match (self.starts.get(i), self.starts.get(i + 1)) {
            (Some(&a), Some(&b)) => a..b,
            _ => 0..0,
        };
        self.partials.range(range)
    }

    /// The parameters these corrections were made at, where a change reads the geometry
    /// (elsewhere they hold at any).
    pub fn made_at(&self) -> Option<&Params> {
        self.geometry.as_ref().map(|g| &g.at)
    }

    /// ∂value/∂p through the corrections, over the 29 parameters, of a value with input
    /// sensitivities `at` (as [`Corrections::theta_row`]): the part of the value's Jacobian
    /// a change that reads the geometry adds to its direct one. Zero where none reads it.
    pub fn p_row(&self, at: &[(usize, InputSensitivity)]) -> Row {
        let mut out = Row::zeros();
        let Some(g) = &self.geometry else {
            return out;
        };
        for (i, s) in at {
            if let (Some(&a), Some(&b)) = (g.starts.get(*i), g.starts.get(i + 1)) {
                for slope in &g.slopes[a..b] {
                    out.axpy(s.dp[slope.param], &slope.dp, 1.0);
                }
            }
        }
        out
    }

    /// The θ index of the first parameter that moves rod 5 otherwise than rod 4 (its length
    /// or a joint by another amount), where any does: a change model 24's perfect
    /// parallel-holder (ψ ≡ γ2, no rod 5 of its own) cannot carry.
    pub fn rod5_apart(&self) -> Option<usize> {
        let (four, five) = (&crate::params::RODS[3], &crate::params::RODS[4]);
        let pairs = [
            (four.l, five.l),
            (four.xa, five.xa),
            (four.ya, five.ya),
            (four.xb, five.xb),
            (four.yb, five.yb),
        ];
        self.partials
            .range(0..self.partials.len())
            .find(|(_, d)| {
                pairs.iter().any(|&(four, five)| {
                    let (a, b) = (d.dp[four], d.dp[five]);
                    (a - b).abs() > 1e-9 * a.abs().max(b.abs())
                })
            })
            .map(|(k, _)| k)
    }

    /// ∂value/∂θ over every effect parameter of a value with input sensitivities `at`
    /// (pairs of pose index and sensitivity: the pose and, for relative instruments, its
    /// setup's reset pose). The partials left out are zero: they would add a zero.
    pub fn theta_row(&self, at: &[(usize, InputSensitivity)]) -> Vec<f64> {
        let mut out = vec![0.0; self.n_params];
        for (i, s) in at {
            for (k, d) in self.partials_of(*i) {
                out[k] += d.chain(s);
            }
        }
        out
    }
}

/// One effect parameter's place in the θ of an [`EffectSet`].
#[derive(Clone, Debug, PartialEq)]
pub struct Slot {
    /// The effect's name.
    pub effect: String,
    pub param: EffectParam,
    /// Index in θ.
    pub index: usize,
    /// One value per setup (an instrument's alignment), not a property of the machine: it
    /// does not carry over to another campaign.
    pub setup_local: bool,
}

/// Effects bound to one campaign, with one parameter vector θ for all of them.
pub struct EffectSet {
    /// Shared, so that a set bound again at other parameters keeps the bindings that do
    /// not change ([`EffectSet::rebound`]).
    bound: Vec<(String, Arc<dyn Bound>)>,
    n_poses: usize,
    /// Parameters held at zero (a part of an effect the data do not support).
    held: Vec<bool>,
}

impl std::fmt::Debug for EffectSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list()
            .entries(self.bound.iter().map(|b| &b.0))
            .finish()
    }
}

impl EffectSet {
    /// No effect.
    pub fn empty() -> EffectSet {
        EffectSet {
            bound: Vec::new(),
            n_poses: 0,
            held: Vec::new(),
        }
    }

    /// The empty set, borrowed for as long as needed (a calibration request without
    /// effects).
    pub fn none() -> &'static EffectSet {
        static NONE: EffectSet = EffectSet {
            bound: Vec::new(),
            n_poses: 0,
            held: Vec::new(),
        };
        &NONE
    }

    /// Whether the set was bound to a campaign of `n_poses` poses (an empty set fits any):
    /// corrections of another campaign would be read at the wrong poses.
    pub fn fits_campaign_of(&self, n_poses: usize) -> bool {
        self.bound.is_empty() || self.n_poses == n_poses
    }

    /// Bind `effects` to `campaign`.
    pub fn bind(
        effects: &[&dyn Effect],
        campaign: &Campaign,
        p: &Params,
    ) -> Result<EffectSet, NotApplicable> {
        let bound = effects
            .iter()
            .map(|e| {
                Ok((
                    e.name().to_owned(),
                    Arc::<dyn Bound>::from(e.bind(campaign, p)?),
                ))
            })
            .collect::<Result<Vec<_>, NotApplicable>>()?;
        let n: usize = bound.iter().map(|b| b.1.params().len()).sum();
        Ok(EffectSet {
            bound,
            n_poses: campaign.poses.len(),
            held: vec![false; n],
        })
    }

    /// Whether a binding of the set reads the geometry at the parameters it was bound with
    /// ([`Bound::rebinds_from`]): a fit that moved them leaves it a model error.
    pub fn rebinds(&self) -> bool {
        self.bound.iter().any(|b| b.1.rebinds_from().is_some())
    }

    /// The set bound again to `campaign` at the parameters `p` and effect parameters `theta`
    /// (a fit's) where a binding reads the geometry ([`EffectSet::rebinds`]): it reads it as
    /// the other effects at `theta` change each pose ([`Effect::bind_among`]). The others and
    /// the held parameters are kept; None where no binding reads the geometry.
    pub fn rebound(
        &self,
        campaign: &Campaign,
        p: &Params,
        theta: &[f64],
    ) -> Option<Result<EffectSet, NotApplicable>> {
        if !self.rebinds() {
            return None;
        }
        let moved = self.moved_by_others(theta);
        let bound = self
            .bound
            .iter()
            .map(|(name, b)| match b.rebinds_from() {
                Some(e) => Ok((
                    name.clone(),
                    Arc::<dyn Bound>::from(e.bind_among(campaign, p, &moved)?),
                )),
                None => Ok((name.clone(), Arc::clone(b))),
            })
            .collect::<Result<Vec<_>, NotApplicable>>();
        Some(bound.map(|bound| EffectSet {
            bound,
            n_poses: self.n_poses,
            held: self.held.clone(),
        }))
    }

    /// Per pose, the change the bindings that read no geometry make at `theta`: the inputs
    /// a binding that reads it is bound among.
    fn moved_by_others(&self, theta: &[f64]) -> Vec<Delta> {
        let others: Vec<(&dyn Bound, &[f64])> = self
            .with_theta(theta)
            .filter(|(b, _, _)| b.rebinds_from().is_none())
            .map(|(b, own, _)| (b, own))
            .collect();
        // the partials are not read: one scratch of the widest binding serves every call
        let widest = others.iter().map(|(_, own)| own.len()).max().unwrap_or(0);
        let mut scratch = vec![Delta::default(); widest];
        (0..self.n_poses)
            .map(|i| {
                let mut value = Delta::default();
                for (b, own) in &others {
                    b.correct(i, own, &mut value, &mut scratch[..own.len()]);
                }
                value
            })
            .collect()
    }

    /// Each binding with its parameters' slice of `theta` and where that slice starts.
    fn with_theta<'a>(
        &'a self,
        theta: &'a [f64],
    ) -> impl Iterator<Item = (&'a dyn Bound, &'a [f64], usize)> {
        self.bound.iter().scan(0, move |k, (_, b)| {
            let start = *k;
            *k += b.params().len();
            Some((b.as_ref(), &theta[start..*k], start))
        })
    }

    /// The same bindings with the anchored parameters ([`EffectParam::anchor`]) held at
    /// zero as well; None where there are none free.
    pub fn without_anchored(&self) -> Option<EffectSet> {
        let layout = self.layout();
        let anchored: Vec<usize> = layout
            .iter()
            .filter(|s| s.param.anchor.is_some() && !self.is_held(s.index))
            .map(|s| s.index)
            .collect();
        if anchored.is_empty() {
            return None;
        }
        let mut out = EffectSet {
            bound: self.bound.clone(),
            n_poses: self.n_poses,
            held: self.held.clone(),
        };
        for k in anchored {
            out.hold(k);
        }
        Some(out)
    }

    /// Hold parameter `k` (θ order) at zero: the calibration does not identify it.
    pub fn hold(&mut self, k: usize) {
        if let Some(h) = self.held.get_mut(k) {
            *h = true;
        }
    }

    /// Whether parameter `k` is held at zero.
    pub fn is_held(&self, k: usize) -> bool {
        self.held.get(k).copied().unwrap_or(false)
    }

    /// Whether there is no effect.
    pub fn is_empty(&self) -> bool {
        self.bound.is_empty()
    }

    /// Number of poses of the campaign the set is bound to (0 for an empty set).
    pub fn n_poses(&self) -> usize {
        self.n_poses
    }

    /// Number of effect parameters.
    pub fn n_params(&self) -> usize {
        self.bound.iter().map(|b| b.1.params().len()).sum()
    }

    /// Effect names in order.
    pub fn names(&self) -> Vec<&str> {
        self.bound.iter().map(|b| b.0.as_str()).collect()
    }

    /// How many effect parameters belong to the campaign's setups ([`Slot::setup_local`]).
    pub fn setup_local_params(&self) -> usize {
        self.layout().iter().filter(|s| s.setup_local).count()
    }

    /// Every effect parameter's place in θ, in θ order.
    pub fn layout(&self) -> Vec<Slot> {
        let mut out = Vec::new();
        for (effect, b) in &self.bound {
            for param in b.params() {
                out.push(Slot {
                    effect: effect.clone(),
                    param: param.clone(),
                    index: out.len(),
                    setup_local: b.setup_local(),
                });
            }
        }
        out
    }

    /// The corrections of every pose for θ, at the geometric parameters `p` (read only by
    /// a binding that reads the geometry, [`Bound::correct_at`]).
    pub fn corrections(&self, theta: &[f64], p: &Params) -> Corrections {
        let n = self.n_params();
        if self.bound.is_empty() {
            return Corrections::default();
        }
        let touched: usize = (0..self.n_poses)
            .map(|i| {
                self.bound
                    .iter()
                    .map(|b| b.1.touched(i).len())
                    .sum::<usize>()
            })
            .sum();
        let mut out = Corrections {
            values: packed::Packed::with_capacity(self.n_poses),
            starts: Vec::with_capacity(self.n_poses + 1),
            partials: packed::Packed::with_capacity(touched),
            n_params: n,
            geometry: None,
        };
        out.starts.push(0);
        let mut slopes = Vec::new();
        let mut slope_starts = vec![0];
        // which bindings read the geometry: they are corrected after the others
        let reads: Vec<bool> = self
            .bound
            .iter()
            .map(|b| b.1.rebinds_from().is_some())
            .collect();
        // one pose's partials, of which each effect zeroes and reads only those it touches
        let mut scratch = vec![Delta::default(); n];
        for i in 0..self.n_poses {
            let mut value = Delta::default();
            // the bindings that read no geometry first: one that reads it reads the pose
            // where they put the machine (as it was bound, `EffectSet::rebound`)
            for pass in [false, true] {
                for ((b, own_theta, k), &reading) in self.with_theta(theta).zip(&reads) {
                    if reading != pass {
                        continue;
                    }
                    let touched = b.touched(i);
                    let own = &mut scratch[k..k + own_theta.len()];
                    own[touched].fill(Delta::default());
                    if reading {
                        let moved = value;
                        b.correct_at(i, own_theta, (p, &moved), &mut value, own, &mut slopes);
                    } else {
                        b.correct(i, own_theta, &mut value, own);
                    }
                }
            }
            let first_slope = *slope_starts.last().unwrap_or(&0);
            for ((b, _, k), &reading) in self.with_theta(theta).zip(&reads) {
                for j in b.touched(i) {
                    let mut d = scratch[k + j];
                    if !reading {
                        // the others' parameters move the pose the stretch was read at
                        chain_through(&mut d, &slopes[first_slope..]);
                    }
                    out.partials.push(k + j, &d);
                }
            }
            out.values.push(i, &value);
            out.starts.push(out.partials.len());
            slope_starts.push(slopes.len());
        }
        if !slopes.is_empty() {
            out.geometry = Some(GeometrySlopes {
                at: *p,
                starts: slope_starts,
                slopes,
            });
        }
        out
    }
}

#[cfg(test)]
mod family_tests {
    use super::*;

    /// Each effect of the registry is its family's, by the family's name, and each family is
    /// one of the registry's: the identity code compares is the name a user writes.
    #[test]
    fn every_registered_effect_is_one_family() {
        let registered = all();
        for e in &registered {
            let family = Family::of(e.name()).expect("a family");
            assert_eq!(family.name(), e.name());
        }
        for f in Family::ALL {
            assert!(registered.iter().any(|e| e.name() == f.name()), "{f:?}");
        }
        assert_eq!(Family::of("thermal:rods+frame"), Some(Family::Thermal));
        assert_eq!(Family::of("rods_lagged"), None);
    }
}
