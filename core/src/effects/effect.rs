//! What an effect is to the model: the [`Effect`] a library entry or an effects file gives,
//! the [`Bound`] it becomes on one campaign, the change of one pose's inputs it makes
//! ([`Delta`]) and the sensitivities that change is chained with. Every effect's file reads
//! this one; it reads none of them.

use crate::campaign::Campaign;
use crate::params::{Params, Row};
use nalgebra::Vector2;

/// Why an effect cannot be added to a model with this campaign.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{effect}: {reason}")]
pub struct NotApplicable {
    pub effect: String,
    pub reason: String,
}

/// One parameter of an effect.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EffectParam {
    /// Name, prefixed by nothing: the effect's name goes with it in reports (`thermal.alpha`).
    pub name: String,
    /// Unit of the value (`ppm/K`, `mm`, `mrad`...).
    pub unit: String,
    /// Plausible magnitude (prior range), in `unit`: the scaling of the parameter in the
    /// least squares and the size a report compares the estimate with.
    pub prior: f64,
    /// The values the physics allows, in `unit` (thermal expansion of real materials, a
    /// compliance that is not negative): an estimate clearly outside absorbs something else.
    /// None: within ten times [`EffectParam::prior`] either way ([`EffectParam::allowed`]).
    pub range: Option<(f64, f64)>,
    /// Where a fit starts, in `unit` (0 for most: no effect).
    pub start: f64,
    /// A nuisance the effect carries, held near zero in the fit by a prior of this σ (in
    /// `unit`): not a physical value (a lagging thermometer's rate error, which the
    /// self-calibration resolves finer than the thermometer gives it). Never carried to
    /// another campaign. None for every physical parameter.
    pub anchor: Option<f64>,
}

impl EffectParam {
    /// A parameter with the default range (ten times its prior either way).
    pub fn new(name: impl Into<String>, unit: impl Into<String>, prior: f64) -> EffectParam {
        EffectParam {
            name: name.into(),
            unit: unit.into(),
            prior,
            range: None,
            start: 0.0,
            anchor: None,
        }
    }

    /// The same as a nuisance held near zero by a prior of σ `sigma` ([`EffectParam::anchor`]).
    #[must_use]
    pub fn anchored(self, sigma: f64) -> EffectParam {
        EffectParam {
            anchor: Some(sigma),
            ..self
        }
    }

    /// The same starting at `start` (its unit).
    #[must_use]
    pub fn starting(self, start: f64) -> EffectParam {
        EffectParam { start, ..self }
    }

    /// The same with the values the physics allows.
    #[must_use]
    pub fn within(self, lo: f64, hi: f64) -> EffectParam {
        EffectParam {
            range: Some((lo, hi)),
            ..self
        }
    }

    /// The values the physics allows: the stated range, or ten times the prior either way.
    pub fn allowed(&self) -> (f64, f64) {
        self.range.unwrap_or((
            -IMPLAUSIBLE_PRIORS * self.prior,
            IMPLAUSIBLE_PRIORS * self.prior,
        ))
    }
}

/// An effect parameter estimated beyond this many times its plausible magnitude ([`EffectParam::prior`])
/// is implausible where the effect states no range of its own.
pub const IMPLAUSIBLE_PRIORS: f64 = 10.0;

/// A physical effect of the library (see the module documentation).
pub trait Effect: Send + Sync {
    /// Name on the command line and in reports (`thermal`).
    fn name(&self) -> &str;
    /// One sentence on what the effect models.
    fn summary(&self) -> &str;
    /// Campaign covariate columns the effect needs (`temp_machine`).
    fn covariates(&self) -> &'static [&'static str] {
        &[]
    }
    /// The parts of a family whose pieces each stand on their own physically (thermal: rods,
    /// frame, scales), one parameter each in this order; empty for an effect of one piece.
    fn parts(&self) -> &'static [&'static str] {
        &[]
    }
    /// The family with only `parts` (indices into [`Effect::parts`], ascending), named
    /// `family:part+part` (`thermal:rods`): a model that keeps the parts a campaign can tell
    /// apart. None for an effect of one piece.
    fn with_parts(&self, parts: &[usize]) -> Option<Box<dyn Effect>> {
        let _ = parts;
        None
    }
    /// Whether the family is named whole (`thermal`) and its parts are left to the data: the
    /// diagnosis and the calibration keep the parts that predict (see
    /// `diagnose::search::settle::settle`). False where the parts are pinned (`thermal:rods`) and for
    /// an effect of one piece.
    fn open_family(&self) -> bool {
        false
    }
    /// Richer variants of the effect, each a parameter more, that the data may need beyond it
    /// (`preload_elastic:rod2`: a rod with a compliance of its own): the diagnosis keeps one
    /// only where the data need it (`diagnose::search::settle`). None, the default, for most.
    fn refinements(&self) -> Vec<Box<dyn Effect>> {
        Vec::new()
    }
    /// The family this effect refines (`thermal` for `thermal_lag`): the diagnosis tries it
    /// only where that family is in the model. None, the default, for an effect of its own.
    fn beside(&self) -> Option<&'static str> {
        None
    }
    /// Whether the effect reads a covariate's history along the campaign's time (its rate or
    /// its lag: `thermal_lag`, a written `rate()` or `lag()`), not only its row's value: the
    /// diagnosis then reads the residual without what the thermometers' noise makes through
    /// that history (`diagnose::structure::carried`). False, the default, for most.
    fn has_memory(&self) -> bool {
        false
    }
    /// Bind the effect to a campaign, with parameters `p` for the geometry it needs to read
    /// its covariates (rod directions for forces): per-pose data are computed once here.
    fn bind(&self, campaign: &Campaign, p: &Params) -> Result<Box<dyn Bound>, NotApplicable>;
    /// [`Effect::bind`] inside a model whose other effects change each pose's inputs by
    /// `moved` (one [`Delta`] per pose, their corrections at the fit's θ): an effect that
    /// reads the geometry reads it where the model puts the machine. A parallel-holder's
    /// rod 5 1.4 mm long shares the preload between rods 4 and 5 otherwise than the perfect
    /// holder does; balanced without it, the compliance of a twin at the default stiffness
    /// came out 1.0164 ± 0.0005 (core/tests/it/calibration_preload_among.rs). The default,
    /// for an effect that reads no geometry, is [`Effect::bind`].
    fn bind_among(
        &self,
        campaign: &Campaign,
        p: &Params,
        moved: &[Delta],
    ) -> Result<Box<dyn Bound>, NotApplicable> {
        let _ = moved;
        self.bind(campaign, p)
    }
}

/// An effect bound to one campaign.
pub trait Bound: Send + Sync {
    /// Its parameters for this campaign (e.g. one angle per instrument setup).
    fn params(&self) -> &[EffectParam];
    /// Whether the parameters belong to the campaign's setups rather than to the machine (an
    /// instrument's alignment): held-out data re-fit them on their own setups instead of
    /// reusing the calibration's values.
    fn setup_local(&self) -> bool {
        false
    }
    /// Add the correction of pose `pose` for parameter values `theta` (this effect's, in the
    /// order of [`Bound::params`]) to `value`, and its derivatives to `partials[k]` = ∂/∂θ_k.
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]);
    /// [`Bound::correct`] at the geometric parameters `p`, the other effects having changed
    /// the pose's inputs by `moved`, for a correction that reads the geometry (the preload's
    /// rod forces balance through the rods' directions): it also pushes how the correction
    /// moves with the pose's parameters and carrier positions to `slopes`. Left out of the
    /// fit's Jacobian, that dependence was a model error the fit could not see: the
    /// parallelogram rods' forces turn by 0.3 % per 0.1 mm of geometry, a few tenths of a
    /// micrometre of stretch against compatibility rows of a third of one, and rebinding
    /// between rounds chased it without converging. The default reads no geometry.
    fn correct_at(
        &self,
        pose: usize,
        theta: &[f64],
        (p, moved): (&Params, &Delta),
        value: &mut Delta,
        partials: &mut [Delta],
        slopes: &mut Vec<Slope>,
    ) {
        let _ = (p, moved, slopes);
        self.correct(pose, theta, value, partials);
    }
    /// The parameters (indices in [`Bound::params`]) whose partials [`Bound::correct`] may
    /// make non-zero at pose `pose`; it writes no other. An instrument's alignment angle
    /// moves only its own setup's poses: the corrections keep 1 partial per pose instead of
    /// one per setup.
    fn touched(&self, pose: usize) -> std::ops::Range<usize> {
        let _ = pose;
        0..self.params().len()
    }
    /// The effect to bind again at a fit's parameters, where this binding read the geometry
    /// at the parameters it was bound with enough that the fit's change it (see
    /// [`EffectSet::rebound`]); None, the default, where the binding at the start serves (it
    /// reads no geometry, or too little to matter).
    fn rebinds_from(&self) -> Option<&dyn Effect> {
        None
    }
}

/// How one geometric input of a pose's correction (`value.dp[param]`) moves with the pose's
/// parameters and carrier positions ([`Bound::correct_at`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slope {
    /// Index into [`Delta::dp`].
    pub param: usize,
    /// ∂/∂p over the 29 parameters ...
    pub dp: Row,
    /// ... and ∂/∂q over the four carrier positions.
    pub dq: [f64; 4],
}

impl Slope {
    /// The change this input makes for a change `d` of the pose's inputs.
    pub fn of(&self, d: &Delta) -> f64 {
        self.dp.dot(&d.dp) + (0..4).map(|a| self.dq[a] * d.dq[a]).sum::<f64>()
    }
}

/// A change of one pose's model inputs (or its derivative with respect to one effect
/// parameter).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Delta {
    /// Geometric parameters, mm and rad.
    pub dp: Row,
    /// Carrier position − encoder reading, mm, q1..q4.
    pub dq: [f64; 4],
    /// True − recorded instrument (x, y), mm.
    pub dm: Vector2<f64>,
    /// True − recorded platform-angle reading (the angle interferometer's ψ), rad.
    pub dpsi: f64,
    /// Relative change of the machine's stiffness (the drive-force rows' springs are
    /// k · (1 + dk)); no other row depends on it.
    pub dk: f64,
}

impl Default for Delta {
    fn default() -> Self {
        Delta {
            dp: Row::zeros(),
            dq: [0.0; 4],
            dm: Vector2::zeros(),
            dpsi: 0.0,
            dk: 0.0,
        }
    }
}

impl Delta {
    /// The parameters `p` and carrier positions `q` (q1..q4) of a pose under this change.
    pub fn applied(&self, p: &Params, q: &[f64; 4]) -> (Params, [f64; 4]) {
        let mut at = *p;
        for (k, v) in self.dp.iter().enumerate() {
            at[k] += v;
        }
        (at, std::array::from_fn(|a| q[a] + self.dq[a]))
    }

    /// The chain rule: the change of a model value with sensitivities `s` for this change.
    pub fn chain(&self, s: &InputSensitivity) -> f64 {
        s.dp.dot(&self.dp)
            + (0..4).map(|a| s.dq[a] * self.dq[a]).sum::<f64>()
            + s.dm.dot(&self.dm)
            + s.dpsi * self.dpsi
            + s.dk * self.dk
    }
}

/// Sensitivity of a model value to one pose's inputs: the 29 parameters used at the pose, its
/// carrier positions and its recorded (x, y).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputSensitivity {
    pub dp: Row,
    pub dq: [f64; 4],
    pub dm: Vector2<f64>,
    /// ... to its recorded platform angle (angle rows only),
    pub dpsi: f64,
    /// ... and to the relative stiffness change (drive-force rows only).
    pub dk: f64,
}

impl Default for InputSensitivity {
    fn default() -> Self {
        InputSensitivity {
            dp: Row::zeros(),
            dq: [0.0; 4],
            dm: Vector2::zeros(),
            dpsi: 0.0,
            dk: 0.0,
        }
    }
}

/// Value of covariate `name` at every pose, or why the effect cannot use it.
pub(crate) fn covariate_column(
    campaign: &Campaign,
    effect: &str,
    name: &str,
) -> Result<Vec<Option<f64>>, NotApplicable> {
    campaign.covariate(name).ok_or_else(|| NotApplicable {
        effect: effect.to_owned(),
        reason: format!(
            "the campaign {} has no covariate column `{name}`",
            campaign.source
        ),
    })
}
