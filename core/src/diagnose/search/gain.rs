//! What an addition to a model gains: the evidence of both campaigns (the calibration's
//! nested F-test with the prediction), whether it is better and not contradicted, its size
//! against the noise, and whether its values are physical. One rule for a candidate against
//! the current model, a model against another, a family's parts against the whole.

use crate::calib::EffectEstimate;
use crate::diagnose::types::Prediction;
use crate::stats;

/// An addition to the model matters when the part of the prediction error it explains,
/// √(RMS_b² − RMS_a²), reaches this share of the noise there: a fifth of the instruments'
/// noise, below which it changes the held-out RMS by less than 2 %. Smaller ones are
/// "statistically detectable, too small to matter" (on a hundred thousand rows every
/// negligible gain passes a fixed-level test).
pub const PRACTICAL_SIZE: f64 = 0.2;

/// A fitted effect parameter beyond the values the physics allows by more than this many of
/// its σ makes the model implausible: it absorbs something else.
pub const PLAUSIBLE_SIGMAS: f64 = 3.0;

/// The nested F-test of a larger model against a smaller one it holds, each (χ², ν): the
/// effective parameters it adds (k = ν_small − ν_big), the F statistic (Δχ²/k) /
/// (χ²_big/ν_big) and its upper tail on (k, ν_big). The one test of a candidate
/// screened, a candidate fitted, a model of the search and a gain.
#[derive(Clone, Copy, Debug)]
pub(in crate::diagnose) struct Nested {
    pub k: f64,
    pub f: f64,
    pub p: f64,
}

impl Nested {
    /// The test of `big` against `small`; None where `big` adds half an effective parameter
    /// or less (no test: a model that adds nothing).
    pub(in crate::diagnose) fn of(big: (f64, f64), small: (f64, f64)) -> Option<Nested> {
        let k = small.1 - big.1;
        if !(k > 0.5) {
            return None;
        }
        let dchi2 = small.0 - big.0;
        let f = (dchi2 / k) / (big.0 / big.1);
        // a fall of χ² that is none (f ≤ 0) is p = 1
        Some(Nested {
            k,
            f,
            p: stats::f_upper_tail(f, k, big.1),
        })
    }
}

/// What a larger model gains over a smaller one it holds: the evidence of both campaigns and
/// its size. One rule for a candidate against the current model, a model against another,
/// a family's parts against the whole.
pub(in crate::diagnose) struct Gain {
    /// The nested F-test's p-value on the calibration campaign.
    p_cal: f64,
    /// RMS of the calibration rows' fall in their own noise, √(Δχ²/n): the size the
    /// calibration itself sees (a fine instrument there, a noisy one held out).
    cal_size: f64,
    /// The prediction (held-out or left-out), its errors each in its own noise (σ).
    prediction: Option<Prediction>,
}

impl Gain {
    /// The gain of a model with χ² `big` over one with `small`, each (χ², dof), on `rows`
    /// calibration rows.
    pub(in crate::diagnose) fn of(
        big: (f64, f64),
        small: (f64, f64),
        rows: usize,
        prediction: Option<Prediction>,
    ) -> Gain {
        let dchi2 = (small.0 - big.0).max(0.0);
        Gain {
            p_cal: Nested::of(big, small).map_or(1.0, |n| n.p),
            cal_size: (dchi2 / rows.max(1) as f64).sqrt(),
            prediction,
        }
    }

    /// The same gain where the added parameters' own test (`wald_p`) is weaker than the
    /// likelihood ratio: the calibration's evidence is the weaker of the two.
    pub(in crate::diagnose) fn with_wald(self, wald: f64) -> Gain {
        Gain {
            p_cal: self.p_cal.max(wald),
            ..self
        }
    }

    /// Fisher's combination of the F-test and the prediction's: whether the predicted errors
    /// support the change the larger model makes ([`Prediction::support_p`]; that it makes
    /// them smaller is [`Gain::better`]'s).
    pub(in crate::diagnose) fn evidence(&self) -> f64 {
        match self.prediction {
            Some(p) => stats::fisher_combined(&[self.p_cal, p.support_p]),
            None => self.p_cal,
        }
    }

    /// The larger of the sizes the two campaigns see, each in its noise.
    pub(in crate::diagnose) fn size(&self) -> f64 {
        let predicted = self.prediction.map_or(0.0, |p| p.explained());
        self.cal_size.max(predicted)
    }

    pub(in crate::diagnose) fn better(&self) -> bool {
        self.prediction.is_none_or(|p| p.better)
    }

    pub(in crate::diagnose) fn worse(&self) -> bool {
        self.prediction.is_some_and(|p| p.worse)
    }

    /// Whether the calibration campaign alone needs the larger model: its F-test at `level`,
    /// by a gain that matters there.
    pub(in crate::diagnose) fn calibration_needs(&self, level: f64) -> bool {
        self.p_cal < level && self.cal_size >= PRACTICAL_SIZE
    }

    pub(in crate::diagnose) fn p_cal(&self) -> f64 {
        self.p_cal
    }

    pub(in crate::diagnose) fn prediction(&self) -> Option<Prediction> {
        self.prediction
    }

    /// Whether the larger model is needed: significant on both campaigns together, not
    /// contradicted, better, by a gain that matters.
    pub(in crate::diagnose) fn needed(&self, level: f64) -> bool {
        self.evidence() < level && self.better() && !self.worse() && self.size() >= PRACTICAL_SIZE
    }
}

/// The parameters fitted clearly outside the values the physics allows.
pub(in crate::diagnose) fn implausible(params: &[EffectEstimate]) -> Vec<String> {
    params
        .iter()
        .filter(|p| p.identified && p.physical())
        .filter(|p| {
            let (lo, hi) = p.allowed;
            p.value - PLAUSIBLE_SIGMAS * p.sigma > hi || p.value + PLAUSIBLE_SIGMAS * p.sigma < lo
        })
        .map(|p| {
            format!(
                "{} = {} ± {} {} outside {}..{}",
                p.name,
                sig(p.value),
                sig(p.sigma),
                p.unit,
                sig(p.allowed.0),
                sig(p.allowed.1)
            )
        })
        .collect()
}

/// A number with three significant digits (the implausibility notes).
pub(in crate::diagnose) fn sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    // digits after the point: 2 for 1.23, 0 for 123, 4 for 0.0123
    let magnitude = v.abs().log10().floor();
    let prec = if magnitude >= 2.0 {
        0
    } else {
        crate::convert::round_count(2.0 - magnitude)
    };
    format!("{v:.prec$}")
}

/// The standard error of the RMS of prediction errors `e` (the spread of the squared errors
/// through d(RMS²) = 2 RMS d(RMS)): the "one standard error" of the best model's
/// prediction, within which a simpler model predicts as well.
pub(crate) fn one_standard_error(e: &[f64]) -> f64 {
    let n = e.len();
    if n < 2 {
        return 0.0;
    }
    let sq: Vec<f64> = e.iter().map(|v| v * v).collect();
    let mean = sq.iter().sum::<f64>() / n as f64;
    let var = sq.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (var / n as f64).sqrt() / (2.0 * mean.sqrt()).max(f64::MIN_POSITIVE)
}

/// The Wald test of the parameters of the effects `added` in `fit`: p of
/// θ_Aᵀ Σ_AA⁻¹ θ_A / k against F(k, ν) over the identified ones. A gain whose parameters
/// are themselves indistinguishable from zero is the geometry's refit from another start,
/// not the effect's: the likelihood ratio alone would name an effect that does nothing.
/// 1 where no added parameter is identified.
pub(in crate::diagnose) fn wald_p(fit: &crate::diagnose::types::Fit, added: &[&str]) -> f64 {
    wald_of(fit, |p| added.contains(&p.effect.as_str()))
}

/// The Wald test of the parameters `big` has beyond `small` (a model it holds): those whose
/// family and name `small` lacks. A larger model whose extra parameters are zero within
/// their σ fits better only by refitting the rest from another start.
pub(in crate::diagnose) fn wald_beyond(
    big: &crate::diagnose::types::Fit,
    small: &crate::diagnose::types::Fit,
) -> f64 {
    let beyond = beyond(small);
    wald_of(big, |p| beyond(p))
}

/// Whether some parameter `big` has beyond `small` (a model it holds) reaches
/// [`crate::diagnose::types::RELEVANT_FRACTION`] of its plausible magnitude: what a larger model adds
/// must matter as a candidate's parameters must (a guides' scale difference of 2 ± 1 ppm
/// beside a soft rod's preload absorbs a residual the library does not have).
pub(in crate::diagnose) fn relevant_beyond(
    big: &crate::diagnose::types::Fit,
    small: &crate::diagnose::types::Fit,
) -> bool {
    let beyond = beyond(small);
    relevant(big.effect_params.iter().filter(|p| beyond(p)))
}

/// Whether some identified parameter of `params` reaches
/// [`crate::diagnose::types::RELEVANT_FRACTION`] of its plausible magnitude (its prior): the size a
/// candidate's, a model's additions and what a larger model adds must have to matter.
pub(in crate::diagnose) fn relevant<'a>(
    params: impl IntoIterator<Item = &'a EffectEstimate>,
) -> bool {
    params
        .into_iter()
        .filter(|p| p.identified && p.physical() && p.prior > 0.0)
        .any(|p| p.value.abs() >= crate::diagnose::types::RELEVANT_FRACTION * p.prior)
}

/// Whether an effect parameter is one `small` lacks (by family and name).
fn beyond(small: &crate::diagnose::types::Fit) -> impl Fn(&EffectEstimate) -> bool {
    let key = |p: &EffectEstimate| {
        (
            crate::effects::family_of(&p.effect).to_owned(),
            p.name.clone(),
        )
    };
    let held: Vec<(String, String)> = small.effect_params.iter().map(key).collect();
    move |p| !held.contains(&key(p))
}

/// The Wald test over the identified parameters of `fit` that `pick` selects.
fn wald_of(fit: &crate::diagnose::types::Fit, pick: impl Fn(&EffectEstimate) -> bool) -> f64 {
    let idx: Vec<usize> = fit
        .effect_params
        .iter()
        .enumerate()
        .filter(|(_, p)| p.identified && p.physical() && p.sigma > 0.0 && pick(p))
        .map(|(k, _)| k)
        .filter(|&k| k < fit.theta.len() && k < fit.covariance_theta.nrows())
        .collect();
    if idx.is_empty() || fit.covariance_theta.ncols() != fit.covariance_theta.nrows() {
        return 1.0;
    }
    let k = idx.len();
    let theta = nalgebra::DVector::from_iterator(k, idx.iter().map(|&i| fit.theta[i]));
    let cov = nalgebra::DMatrix::from_fn(k, k, |a, b| fit.covariance_theta[(idx[a], idx[b])]);
    // Σ_AA is positive definite for identified parameters; where rounding says otherwise,
    // each parameter alone (the diagonal) is the test
    let w = match cov.clone().cholesky() {
        Some(c) => theta.dot(&c.solve(&theta)),
        None => idx
            .iter()
            .map(|&i| (fit.theta[i] / fit.effect_params[i].sigma).powi(2))
            .sum(),
    };
    stats::f_upper_tail(w / k as f64, k as f64, fit.dof)
}
