//! The calibration's vocabulary: what a caller asks for ([`Options`], [`Selection`],
//! [`Prior`], [`Link`], [`WarmStart`]), what it gets ([`Calibration`] and its parts) and how it
//! fails ([`CalibrationError`]). Every file of calib reads these and none of them reads
//! another file of calib, so the work below flows one way.

use crate::noise::NoiseModel;
use crate::obs::{PoseError, RowValue};
use crate::params::{self, unit, Model, Params, Unit, N_PARAMS};
use nalgebra::{DMatrix, SMatrix};

/// Which parameters the calibration identifies.
#[derive(Clone, Debug, PartialEq)]
pub enum Selection {
    /// From the observability analysis of the campaign: parameters in QR-pivot order while
    /// the condition number stays below `max_condition` (100 after Schröer).
    Auto { max_condition: f64 },
    /// An explicit list of parameter indexes.
    List(Vec<usize>),
    /// Every parameter of the model, each pulled towards its nominal value by its
    /// manufacturing tolerance (maximum a posteriori): the campaign determines the parameter
    /// combinations it sees better than the tolerance, the others stay at the prior. No
    /// condition-number cut to choose, so every command calibrates the same way.
    Prior(Prior),
}

/// Manufacturing tolerances of the geometric parameters (one standard deviation): the prior
/// of a [`Selection::Prior`] calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    pub length_mm: f64,
    pub angle_rad: f64,
}

impl Default for Prior {
    /// 0.1 mm and 1 mrad: a machined and assembled frame of this size.
    fn default() -> Self {
        Prior {
            length_mm: 0.1,
            angle_rad: 1e-3,
        }
    }
}

impl Prior {
    /// The tolerance of parameter `i` (mm or rad).
    pub fn sigma(&self, i: usize) -> f64 {
        match unit(i) {
            Unit::Mm => self.length_mm,
            Unit::Rad => self.angle_rad,
        }
    }
}

/// Parameter scaling (eq. 3.23-3.25).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Scaling {
    /// h_k = 1 / ‖J_k‖: column norms of the weighted Jacobian.
    #[default]
    ColumnNorm,
    /// h_k = the parameter's plausible variation (0.1 mm, 1°), after Schröer.
    Range,
}

/// A linked parameter (a row of the dependency matrix D, eq. 3.35): Δp_param = Σ a·Δp_j.
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    pub param: usize,
    pub terms: Vec<(usize, f64)>,
}

impl Link {
    /// The perfect parallel-holder as links: rod 5 follows rod 4 (l5 = l4, xa5r = xa4r, ...).
    pub fn perfect_parallelogram() -> Vec<Link> {
        use params::{L4, L5, XA4R, XA5R, XB4R, XB5R, YA4R, YA5R, YB4R, YB5R};
        [
            (L5, L4),
            (XA5R, XA4R),
            (YA5R, YA4R),
            (XB5R, XB4R),
            (YB5R, YB4R),
        ]
        .into_iter()
        .map(|(p, j)| Link {
            param: p,
            terms: vec![(j, 1.0)],
        })
        .collect()
    }
}

/// Options of a calibration.
#[derive(Clone, Debug)]
pub struct Options {
    pub model: Model,
    pub selection: Selection,
    pub links: Vec<Link>,
    pub scaling: Scaling,
    /// Rows further than this many standard deviations from their direction's mean are
    /// eliminated (eq. 3.31-3.32); None keeps every row.
    pub outlier_sigma: Option<f64>,
    pub max_iterations: usize,
    /// The instruments' and encoders' noise: the rows' weights.
    pub noise: NoiseModel,
    /// How many times `noise` exceeds the instruments' stated noise at most (1: the stated
    /// noise itself). An effect parameter is held where a value of its prior size would not
    /// move the fit by one standard deviation of what the instruments resolve: a noise
    /// estimated under a model that misses an effect holds that misfit too, and judged
    /// against it the very effect that explains the misfit would look too small to see.
    pub noise_inflation: f64,
    /// Threads the rows are evaluated on (0: every core). The result is the same to the bit
    /// on any number: the rows are summed in fixed pieces, in order.
    pub threads: usize,
    /// Set from another thread to stop the calibration: it returns
    /// [`CalibrationError::Cancelled`] at its next LM iteration. Every fit made with these
    /// options shares it (a diagnosis's, on its own threads, where the caller's
    /// [`super::Request::progress`] observer cannot go).
    pub stop: Option<Stop>,
}

/// A request to stop, shared between the thread that asks and the fits that obey.
#[derive(Clone, Debug, Default)]
pub struct Stop(std::sync::Arc<std::sync::atomic::AtomicBool>);

impl Stop {
    /// Asks every fit that shares this to stop.
    pub fn request(&self) {
        self.0.store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether a stop was asked.
    pub fn requested(&self) -> bool {
        self.0.load(std::sync::atomic::Ordering::Relaxed)
    }
}

impl Default for Options {
    fn default() -> Self {
        Options {
            model: Model::M29,
            selection: Selection::Prior(Prior::default()),
            links: Vec::new(),
            scaling: Scaling::ColumnNorm,
            outlier_sigma: Some(3.0),
            // a model far from the data (a missing effect of 10⁷ χ², what a diagnosis meets)
            // takes the LM longer; a good one stops in a handful
            max_iterations: 400,
            noise: NoiseModel::default(),
            noise_inflation: 1.0,
            threads: 0,
            stop: None,
        }
    }
}

/// Why a calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    #[error(transparent)]
    Pose(#[from] PoseError),
    #[error("{0}: the campaign has no calibration measurements (only circle/none rows or resets)")]
    NoMeasurements(String),
    #[error("{campaign}: the effects were bound to a campaign of {bound} poses, not to this one of {poses}")]
    EffectsOfAnotherCampaign {
        campaign: String,
        bound: usize,
        poses: usize,
    },
    #[error("{given} starting effect parameters given, the effects have {expected} (or give none: all zero)")]
    StartThetaLength { given: usize, expected: usize },
    #[error("parameter {0} does not belong to {1}")]
    NotInModel(&'static str, Model),
    #[error(
        "{effect} moves rod 5 otherwise than rod 4 ({why}), and model 24's perfect parallel-holder \
         (platform angle = gamma2) has no rod 5 of its own to carry that: calibrate model 29 with \
         rod 5 tied to rod 4 (rpkm calibrate --model 29 --perfect-parallelogram; what rpkm diagnose \
         calls model 24)"
    )]
    Rod5OfItsOwn { effect: String, why: String },
    #[error("parameter {0} has no influence on these measurements (zero Jacobian column)")]
    Unobservable(&'static str),
    #[error("no parameter is observable with this campaign")]
    NothingToIdentify,
    #[error("more parameters ({params}) than measurement rows ({rows})")]
    Underdetermined { params: usize, rows: usize },
    #[error("Levenberg-Marquardt did not converge in {iterations} iterations (cost {cost:.4e}, gradient {gradient:.3e})")]
    NotConverged {
        iterations: usize,
        cost: f64,
        gradient: f64,
    },
    #[error(
        "the normal equations are singular: identified parameters are linearly dependent ({0})"
    )]
    Singular(String),
    #[error("{campaign}:{line} ({instrument}): the pose's model-minus-measurement is not finite ({value}); its readings are beyond any machine")]
    NonFiniteRow {
        campaign: String,
        line: usize,
        instrument: &'static str,
        value: f64,
    },
    #[error("the calibration's result is not a number: {0} (the rows carry non-finite values or weights)")]
    NonFinite(String),
    /// Its caller's observer asked it to stop (`Flow::Stop`, `progress`): no result.
    #[error("the calibration was cancelled by its caller")]
    Cancelled,
}

/// A row removed as an outlier.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Outlier {
    /// Source line of the pose.
    pub line: usize,
    pub instrument: String,
    pub direction: String,
    /// Residual at removal, mm (rad for ψ).
    pub residual: f64,
    /// Its distance from the direction's mean in standard deviations.
    pub deviations: f64,
}

/// RMS of one instrument and direction.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DirectionRms {
    pub instrument: String,
    pub direction: String,
    pub rows: usize,
    /// mm, or rad for ψ, or N for a drive force.
    pub rms_before: f64,
    pub rms_after: f64,
    pub is_angle: bool,
    /// A drive force (N).
    pub is_force: bool,
}

/// One identified parameter.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Identified {
    pub name: &'static str,
    pub index: usize,
    pub nominal: f64,
    pub value: f64,
    pub sigma: f64,
    /// Which step identified it: 1 (direct rows) or 2 (virtual q2 rows of forward instruments).
    pub step: u8,
}

/// One parameter of an effect in the model.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EffectEstimate {
    pub effect: String,
    pub name: String,
    pub unit: String,
    pub value: f64,
    pub sigma: f64,
    /// Fraction (0..1) of the parameter's signature in the measurements that the geometric
    /// parameters (and the effect parameters before it) cannot mimic: near 0, the campaign
    /// cannot tell it from a geometric error and it is held at its start value.
    pub observability: f64,
    /// Whether it was identified (false: held, unobservable with this campaign).
    pub identified: bool,
    /// Why it was not identified, in a sentence (`no sensitivity at its start 0 s ...`);
    /// None where it was.
    pub held: Option<String>,
    /// The plausible magnitude the effect declares for it (its unit).
    pub prior: f64,
    /// The values the physics allows ([`crate::effects::EffectParam::allowed`]).
    pub allowed: (f64, f64),
    /// A nuisance of this campaign held near zero by a prior
    /// ([`crate::effects::EffectParam::anchor`]: a lagging thermometer's rate error), not a
    /// property of the machine: no report lists it, no test weighs it, no other campaign
    /// carries it.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub anchored: bool,
}

impl EffectEstimate {
    /// Whether it is a property of the machine (not an anchored nuisance of the campaign).
    pub fn physical(&self) -> bool {
        !self.anchored
    }
}

/// The anchored parameters of one effect ([`EffectEstimate::anchored`]): how many, and how
/// far the fit took them from zero against their priors.
#[derive(Clone, Debug, PartialEq)]
pub struct AnchoredTerms {
    pub effect: String,
    pub terms: usize,
    /// Their name without the term's number (`rate_error_`), and their unit.
    pub stem: String,
    pub unit: String,
    /// The RMS of value/prior over the terms: about 1 where the nuisance is as large as its
    /// prior says.
    pub over_prior: f64,
}

/// The anchored parameters of each effect that has some, in the effects' order.
pub fn anchored_terms(effects: &[EffectEstimate]) -> Vec<AnchoredTerms> {
    let mut names: Vec<&str> = Vec::new();
    for e in effects.iter().filter(|e| e.anchored) {
        if !names.contains(&e.effect.as_str()) {
            names.push(&e.effect);
        }
    }
    names
        .iter()
        .filter_map(|name| {
            let terms: Vec<&EffectEstimate> = effects
                .iter()
                .filter(|e| e.anchored && e.effect == *name)
                .collect();
            let first = terms.first()?;
            let over_prior = (terms
                .iter()
                .map(|e| (e.value / e.prior.max(f64::MIN_POSITIVE)).powi(2))
                .sum::<f64>()
                / terms.len() as f64)
                .sqrt();
            Some(AnchoredTerms {
                effect: (*name).to_owned(),
                terms: terms.len(),
                stem: first
                    .name
                    .trim_end_matches(|c: char| c.is_ascii_digit())
                    .to_owned(),
                unit: first.unit.clone(),
                over_prior,
            })
        })
        .collect()
}

/// The result of a calibration.
#[derive(Clone, Debug)]
pub struct Calibration {
    pub model: Model,
    pub start: Params,
    pub params: Params,
    pub identified: Vec<Identified>,
    pub iterations: usize,
    /// Whether the LM stopped after one confirmed screening step from a warm start instead
    /// of converging ([`WarmStart::screen`]).
    pub screened: bool,
    /// Condition number of the column-normalised weighted Jacobian of the identified
    /// parameters (step 1).
    pub condition_number: f64,
    pub outliers: Vec<Outlier>,
    pub rms: Vec<DirectionRms>,
    /// Weighted cost ½ Σ (r/σ)² before and after; the chi-square per degree of freedom after.
    pub cost_before: f64,
    pub cost_after: f64,
    pub chi2_per_dof: f64,
    pub rows: usize,
    /// Effect parameters θ (all of them, in [`EffectSet::layout`] order) and their estimates.
    pub theta: Vec<f64>,
    pub effects: Vec<EffectEstimate>,
    /// Degrees of freedom used: identified geometric and effect parameters.
    pub n_identified: usize,
    /// Effective number of parameters the data determine (the trace of the hat matrix):
    /// `n_identified` without a prior, less where the prior holds a combination.
    pub dof_model: f64,
    /// With a prior: how many parameter combinations the campaign determined better than
    /// their tolerance, out of how many.
    pub determined: Option<(usize, usize)>,
    /// The final rows of step 1 (the measurements) and their leverages (diagonal of the
    /// hat matrix), for the noise estimation; no leverages where the request asked for
    /// none ([`super::Request::leverages`]).
    pub residuals: Vec<RowValue>,
    pub leverage: Vec<f64>,
    /// Posterior covariance of the 29 parameters (mm, rad, scaled by the variance factor as
    /// the σ of `identified`), with the correlations the campaign left between them: a
    /// campaign pins combinations, and the σ alone would let a later estimator (the online
    /// tracker) move what the campaign had pinned. Rows and columns of parameters not
    /// identified are zero (held at their start value).
    pub covariance: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// The effect parameters' covariance (θ × θ, in [`EffectSet::layout`] order, their
    /// units) and theirs with the 29 (29 × θ), from step 1: what a prediction's uncertainty
    /// needs where an effect and the geometry trade off (thermal expansion against the
    /// lengths it scales). Zero for parameters held.
    pub covariance_theta: DMatrix<f64>,
    pub covariance_p_theta: DMatrix<f64>,
}

/// Where the LM starts when not at the start parameters: the fit of a neighbouring model.
/// The start parameters stay the prior's centre and the "before" of the report; only the
/// path changes (the diagnosis starts each candidate at the current model's fit, two or
/// three steps from its own minimum instead of five).
#[derive(Clone, Copy, Debug)]
pub struct WarmStart<'a> {
    pub params: &'a Params,
    /// The effects' parameters (as many as the effects have).
    pub theta: &'a [f64],
    /// Stop after the first step if the rows confirm it (the LM's predicted reduction
    /// realised within 2 %): from the neighbour's minimum that is the Gauss-Newton step of
    /// the linearised problem, what the diagnosis screens its candidates with. Where the
    /// step is not confirmed the fit goes on to convergence as without it.
    pub screen: bool,
}

/// The unknowns of a calibration: geometric parameters and effect parameters.
#[derive(Clone, Debug)]
pub(super) struct State {
    pub p: Params,
    pub theta: Vec<f64>,
}
