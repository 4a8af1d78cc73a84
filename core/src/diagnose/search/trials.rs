//! The candidate trials: every effect of the library (and the user's written ones) added to
//! the current model and fitted, on a work queue over the cores. Each first takes one
//! Gauss-Newton step from the current model's minimum (the score test of the effect) and is
//! fitted to convergence only where it may be significant ([`SCREEN_P`]); each is then
//! compared with the current model by the nested F-test ([`compare`]).

use super::gain::Nested;
use crate::calib::{self, Calibration, CalibrationError, EffectEstimate, Request, SharedRows};
use crate::campaign::Campaign;
use crate::diagnose::figures::length_values;
use crate::diagnose::held_out::figures::HeldOut;
use crate::diagnose::held_out::validation::Validation;
use crate::diagnose::held_out::Model1;
use crate::diagnose::structure::sparse;
use crate::diagnose::types::{
    Candidate, ErrorVector, Fit, FitError, Fitted, Judged, Prediction, Skipped,
};
use crate::effects::{self, Effect, EffectSet, NotApplicable};
use crate::params::Params;

/// What trying every candidate gave.
pub(crate) struct Round {
    /// Each tried effect compared with the current model.
    pub candidates: Vec<Candidate>,
    /// Each compared effect's fit (the whole family, as the loop adds it), by effect name.
    pub fits: Vec<(String, Fitted)>,
    /// The effects that could not be tried, and why.
    pub skipped: Vec<Skipped>,
    /// The current model's TCP error vectors (2-D relative instruments), or why there are
    /// none (a pose whose forward model has no solution).
    pub vectors: Result<Vec<ErrorVector>, String>,
}

impl Default for Round {
    fn default() -> Self {
        Round {
            candidates: Vec::new(),
            fits: Vec::new(),
            skipped: Vec::new(),
            vectors: Ok(Vec::new()),
        }
    }
}

/// A candidate effect's fits: the full effect and the parts of it kept.
type Tried = Result<(Fitted, Fitted), FitError>;

/// Each effect of `tried` added to the model and fitted, in `tried`'s order, on `threads`
/// threads (0: every core). Each fit is independent and lands at its own index: the result
/// does not depend on the number of threads, nor on which thread fitted which candidate.
pub(crate) fn try_all(
    campaign: &Campaign,
    val: Option<&Validation>,
    (in_model, base): (&[&dyn Effect], &Fit),
    tried: &[&dyn Effect],
    copts: &calib::Options,
    (threads, screen): (usize, bool),
) -> Vec<Tried> {
    let start = Params::nominal();
    // each candidate's model bound once, here: its size orders the work below
    let bound: Vec<Result<EffectSet, NotApplicable>> = tried
        .iter()
        .map(|e| EffectSet::bind(&with_effect(in_model, *e), campaign, &start))
        .collect();
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let threads = if threads == 0 { cores } else { threads }.clamp(1, tried.len().max(1));
    let trials = Trials {
        campaign,
        val,
        in_model,
        base,
        start,
        screen,
        shared: shared_rows(campaign, (in_model, base), tried, &bound, copts),
        copts: calib::Options {
            // the candidates share the cores: each fit's rows on one thread
            threads: if threads == 1 { copts.threads } else { 1 },
            ..copts.clone()
        },
    };
    let mut out: Vec<Option<Tried>> = (0..tried.len()).map(|_| None).collect();
    let mut queue: Vec<(usize, EffectSet)> = Vec::new();
    for (i, set) in bound.into_iter().enumerate() {
        match set {
            Ok(set) => queue.push((i, set)),
            Err(e) => out[i] = Some(Err(e.into())),
        }
    }
    // largest first (the setup-local parameters of an instrument's alignment cost more than
    // all the other candidates together on a campaign of many setups), each thread taking
    // the next one when it is free: the last to finish is a small one
    queue.sort_by_key(|(i, set)| (std::cmp::Reverse(set.n_params()), *i));
    let one = |i: usize, set: EffectSet| trials.try_effect(tried[i], set);
    for (i, fit) in run_queue(queue, threads, &one) {
        out[i] = Some(fit);
    }
    out.into_iter().flatten().collect()
}

/// Most poses whose rows every candidate shares ([`shared_rows`]). The shared rows hold two
/// evaluations of every row with the effect columns of every candidate, and their making the
/// corrections of every pose with all of them at once: on 10⁵ self-calibration poses some
/// 0.6 GB at the diagnosis's peak, where the candidates' own evaluations (on the cores' few
/// fits at a time) hold a fraction of it; the rows are the same either way.
const SHARED_ROWS_MAX_POSES: usize = 20_000;

/// The rows at the start and at the current model's minimum with the effect columns of
/// every candidate that binds (`bound`), evaluated once for all of them; None where they
/// cannot be evaluated (each candidate then evaluates its own rows and reports why that
/// failed) or where the campaign is larger than [`SHARED_ROWS_MAX_POSES`].
fn shared_rows(
    campaign: &Campaign,
    (in_model, base): (&[&dyn Effect], &Fit),
    tried: &[&dyn Effect],
    bound: &[Result<EffectSet, NotApplicable>],
    copts: &calib::Options,
) -> Option<SharedRows> {
    if campaign.poses.len() > SHARED_ROWS_MAX_POSES {
        return None;
    }
    let start = Params::nominal();
    let mut union: Vec<&dyn Effect> = in_model.to_vec();
    union.extend(
        tried
            .iter()
            .zip(bound)
            .filter(|(_, b)| b.is_ok())
            .map(|(e, _)| *e),
    );
    let set = EffectSet::bind(&union, campaign, &start).ok()?;
    let theta = warm_theta(&set, base);
    SharedRows::new(campaign, &start, copts, &set, (&base.params, &theta)).ok()
}

/// What every candidate of a round shares.
pub(crate) struct Trials<'a> {
    campaign: &'a Campaign,
    val: Option<&'a Validation<'a>>,
    in_model: &'a [&'a dyn Effect],
    /// The current model's fit: where each candidate starts, and what it is tested against.
    base: &'a Fit,
    start: Params,
    /// Whether candidates are screened first ([`DiagnosisOptions::screen`]).
    screen: bool,
    copts: calib::Options,
    /// The rows at the start and at the current model's minimum ([`shared_rows`]).
    shared: Option<SharedRows>,
}

/// `in_model` and `effect`: a candidate's model.
pub(crate) fn with_effect<'a>(
    in_model: &[&'a dyn Effect],
    effect: &'a dyn Effect,
) -> Vec<&'a dyn Effect> {
    let mut with = in_model.to_vec();
    with.push(effect);
    with
}

/// `one` applied to every (index, set) of `queue`, in order, on `threads` threads that each
/// take the next entry when free; the results with their indexes, in no particular order.
fn run_queue<T: Send>(
    queue: Vec<(usize, EffectSet)>,
    threads: usize,
    one: &(impl Fn(usize, EffectSet) -> T + Sync),
) -> Vec<(usize, T)> {
    if threads <= 1 {
        return queue.into_iter().map(|(i, set)| (i, one(i, set))).collect();
    }
    let queue = std::sync::Mutex::new(queue.into_iter());
    // a poisoned lock is a panic in another worker, which the join below passes on
    let next = || queue.lock().ok().and_then(|mut q| q.next());
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                let next = &next;
                scope.spawn(move || {
                    std::iter::from_fn(next)
                        .map(|(i, set)| (i, one(i, set)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            // a panic in a fit is a bug: it goes on in this thread
            .flat_map(|w| w.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    })
}

/// Compare every tried effect's fit with `base`.
pub(crate) fn candidates(
    campaign: &Campaign,
    tried: &[&dyn Effect],
    tries: Vec<Tried>,
    base: &Fitted,
    level: f64,
) -> Round {
    let mut out = Round::default();
    for (effect, fit) in tried.iter().zip(tries) {
        let skip = |reason: String| Skipped {
            effect: effect.name().to_owned(),
            reason,
        };
        match fit {
            Ok((full, kept)) => match compare(base, &full, &kept, *effect, campaign, level) {
                Some(c) => {
                    out.candidates.push(c);
                    out.fits.push((effect.name().to_owned(), full));
                }
                None => out.skipped.push(skip(
                    "no parameter of it is observable with this campaign (the geometry \
                     absorbs its signature)"
                        .to_owned(),
                )),
            },
            Err(e) => out.skipped.push(skip(e.to_string())),
        }
    }
    out
}

/// A candidate whose screening fit leaves its F-test's p-value above this is no contender:
/// its figures are the screening fit's. Below it the candidate is fitted to convergence, so
/// that every candidate that can be significant (level α/m ≤ 1e-3) or can be the verdict is
/// judged on its converged fit. The screen's Δχ² is a lower bound of the converged one (the
/// screened point is one the converged fit could have stopped at), so the margin from
/// 1e-3 to 0.05 is for the linearisation alone: one step from the current model's minimum
/// moves the χ² within 1e-3 relative of the converged value on the twin's campaigns.
pub const SCREEN_P: f64 = 0.05;

impl Trials<'_> {
    /// Fit `effect` added to the model (`set`: the model with it, bound): the whole family,
    /// and the parts the data support. First one LM step from the current model's minimum
    /// (the candidate's own parameters at zero, nearly Gauss-Newton's step: the score test of
    /// the effect, linearised where the current model ended); a candidate that is then far
    /// from significance ([`SCREEN_P`]) keeps that fit, any other is fitted to convergence.
    fn try_effect(&self, effect: &dyn Effect, mut set: EffectSet) -> Tried {
        let (val, base) = (self.val, self.base);
        let with = with_effect(self.in_model, effect);
        // the screening step; where the rows did not confirm it, this is the converged fit
        let cal = self.fit(&set, self.screen)?;
        let cal = if cal.screened {
            let screened = finish_with(val, &with, &set, cal)?;
            if screen_p_value(base, &screened.fit) > SCREEN_P {
                let kept = Fitted {
                    rows: screened.rows.clone(),
                    fit: screened.fit.clone(),
                };
                return Ok((screened, kept));
            }
            // a contender: fitted to convergence from the current model, as without the
            // screen
            self.fit(&set, false)?
        } else {
            cal
        };
        // parts of an effect the data do not support: held at zero in the kept variant (a
        // family's parts are the model search's: each tried on its own)
        let weak = if effect.parts().is_empty() {
            weak_parts(&cal, &set, effect.name())
        } else {
            Vec::new()
        };
        let full = finish_with(val, &with, &set, cal)?;
        if weak.is_empty() {
            let kept = Fitted {
                rows: full.rows.clone(),
                fit: full.fit.clone(),
            };
            return Ok((full, kept));
        }
        for k in weak {
            set.hold(k);
        }
        let cal = self.fit(&set, false)?;
        let kept = finish_with(val, &with, &set, cal)?;
        Ok((full, kept))
    }

    /// The model `set` calibrated from the current model's minimum, its own parameters at
    /// zero (`screen`: [`calib::WarmStart::screen`]).
    fn fit(&self, set: &EffectSet, screen: bool) -> Result<Calibration, CalibrationError> {
        let (campaign, start, copts) = (self.campaign, &self.start, &self.copts);
        let theta = warm_theta(set, self.base);
        let warm = calib::WarmStart {
            params: &self.base.params,
            theta: &theta,
            screen,
        };
        calib::calibrate(&Request {
            effects: set,
            warm: Some(warm),
            shared: self.shared.as_ref(),
            // a candidate's leverages are never read (the noise rounds' are the current
            // model's)
            leverages: false,
            ..Request::new(campaign, start, copts)
        })
        .map(|(cal, _)| cal)
    }
}

/// The nested F-test's p-value of a screening fit against the current model (1 when the
/// effect adds no effective parameter or lowers nothing: no contender).
fn screen_p_value(base: &Fit, screened: &Fit) -> f64 {
    Nested::of((screened.chi2, screened.dof), (base.chi2, base.dof)).map_or(1.0, |n| n.p)
}

/// The effect parameters of a fit (`base`) laid out for `set`: each slot takes the value of
/// the slot of the same family and name (`thermal:rods`'s alpha_rods starts at `thermal`'s),
/// a slot the fit does not have starts at its parameter's start (zero for most).
pub(crate) fn warm_theta(set: &EffectSet, base: &Fit) -> Vec<f64> {
    warm_theta_among(set, &[base])
}

/// [`warm_theta`] from the first of `fits` where the slot is not zero (zero where each fit
/// that has it holds it there, its start where none has it).
pub(crate) fn warm_theta_among(set: &EffectSet, fits: &[&Fit]) -> Vec<f64> {
    set.layout()
        .iter()
        .map(|slot| {
            let values: Vec<f64> = fits
                .iter()
                .filter_map(|fit| {
                    fit.effect_params.iter().find(|e| {
                        effects::family_of(&e.effect) == effects::family_of(&slot.effect)
                            && e.name == slot.param.name
                    })
                })
                .map(|e| e.value)
                .collect();
            match values.iter().find(|v| **v != 0.0) {
                Some(v) => *v,
                None if values.is_empty() => slot.param.start,
                None => 0.0,
            }
        })
        .collect()
}

/// θ indexes of `effect`'s machine parameters below 2σ, when it has several identified (the
/// strongest is always kept).
fn weak_parts(cal: &Calibration, set: &EffectSet, effect: &str) -> Vec<usize> {
    let own: Vec<(usize, f64)> = set
        .layout()
        .iter()
        .filter(|slot| slot.effect == effect && !slot.setup_local)
        .filter(|slot| cal.effects[slot.index].identified && cal.effects[slot.index].physical())
        .map(|slot| {
            let e = &cal.effects[slot.index];
            (
                slot.index,
                if e.sigma > 0.0 {
                    (e.value / e.sigma).abs()
                } else {
                    0.0
                },
            )
        })
        .collect();
    if own.len() < 2 {
        return Vec::new();
    }
    let strongest = own.iter().map(|o| o.1).fold(0.0, f64::max);
    own.iter()
        .filter(|o| o.1 < 2.0 && o.1 < strongest)
        .map(|o| o.0)
        .collect()
}

/// The statistics of a calibration with `effects` (bound again to read its layout).
pub(crate) fn finish(
    campaign: &Campaign,
    val: Option<&Validation>,
    effects: &[&dyn Effect],
    cal: Calibration,
) -> Result<Fitted, FitError> {
    let set = EffectSet::bind(effects, campaign, &cal.start)?;
    finish_with(val, effects, &set, cal)
}

/// The statistics of a calibration `cal` of the effects bound in `set`.
pub(crate) fn finish_with(
    val: Option<&Validation>,
    effects: &[&dyn Effect],
    set: &EffectSet,
    cal: Calibration,
) -> Result<Fitted, FitError> {
    let held_out = val
        .map(|v| {
            Model1 {
                effects,
                cal_set: set,
                cal: &cal,
            }
            .evaluate(v)
        })
        .transpose()?;
    Ok(finish_held(held_out, set, cal))
}

/// The statistics of a calibration `cal` of the effects bound in `set` whose held-out
/// figures are `held_out`.
pub(crate) fn finish_held(held_out: Option<HeldOut>, set: &EffectSet, cal: Calibration) -> Fitted {
    // The calibration is spent here: its rows and parameters move into the fit.
    let rows = cal.residuals;
    let chi2: f64 = rows.iter().map(|r| (r.value / r.sigma).powi(2)).sum();
    let dof = (rows.len() as f64 - cal.dof_model).max(1.0);
    let fit = Fit {
        chi2,
        dof,
        chi2_per_dof: chi2 / dof,
        cal_rms: calib::rms(&length_values(&rows)),
        held_out,
        setup_params: set.setup_local_params(),
        effect_params: cal.effects,
        determined: cal.determined,
        params: cal.params,
        theta: cal.theta,
        covariance_theta: cal.covariance_theta,
    };
    Fitted {
        rows: std::sync::Arc::new(rows),
        fit,
    }
}

/// The candidate's comparison with the current model (the F-test on the whole family
/// `full`, the figures of the parts `kept`); None if the effect added no parameter.
fn compare(
    base: &Fitted,
    full: &Fitted,
    kept: &Fitted,
    effect: &dyn Effect,
    campaign: &Campaign,
    level: f64,
) -> Option<Candidate> {
    let Nested {
        k, f, p: p_value, ..
    } = Nested::of((full.fit.chi2, full.fit.dof), (base.fit.chi2, base.fit.dof))?;
    let kept_k = (base.fit.dof - kept.fit.dof).max(0.0);
    let kept_dchi2 = base.fit.chi2 - kept.fit.chi2;
    let excess = base.fit.chi2 - base.fit.dof;
    let explained_fraction = if excess > 0.0 {
        (kept_dchi2 / excess).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let n = base.rows.len() as f64;
    let name = effect.name();
    let params: Vec<EffectEstimate> = kept
        .fit
        .effect_params
        .iter()
        .filter(|e| e.effect == name)
        .cloned()
        .collect();
    let follows = sparse::follows(campaign, &base.rows, effect.covariates());
    let relevant = super::gain::relevant(&params);
    Some(Candidate {
        effect: name.to_owned(),
        significant: p_value < level,
        relevant,
        explained_fraction,
        val_rms_before: base.fit.held_out.as_ref().map(|h| h.errors.rms),
        val_rms_after: full.fit.held_out.as_ref().map(|h| h.errors.rms),
        chi2_per_dof_after: kept.fit.chi2_per_dof,
        f_statistic: f,
        f_dof: (k, full.fit.dof),
        p_value,
        bic_gain: kept_dchi2 - kept_k * n.ln(),
        params,
        chi2_per_dof_before: base.fit.chi2_per_dof,
        follows,
        // judged as the loop will add it: the whole family (the next diagnosis fits every
        // part), not the parts this campaign supports
        prediction: Prediction::held_out(&base.fit, &full.fit),
        cross_validated: None,
        judged: Judged::default(),
    })
}
