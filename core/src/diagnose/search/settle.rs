//! A family of the current model named whole, settled: it keeps the part combination the
//! evidence needs ([`settle`]), judged by the same rule as a candidate (`gain`); an effect
//! with refinements keeps the one the data need, if any.

use super::cross;
use super::gain::{relevant_beyond, wald_beyond, Gain};
use super::trials::finish_with;
use crate::calib::{self, Request};
use crate::campaign::Campaign;
use crate::diagnose::held_out::validation::Validation;
use crate::diagnose::types::{Fit, Prediction, Undecided};
use crate::effects::{held_parts, Effect, EffectSet};
use crate::params::Params;

/// A family's part combinations a settle compares (thermal's three parts: seven), the
/// Bonferroni count of its evidence.
pub const PART_COMBINATIONS: f64 = 7.0;

/// The current model with its families named whole settled: each keeps the parts (and
/// combination of parts) that predicts held-out data best, else the setups cross-validation
/// leaves out, the simplest within one standard error of the best. A family stays whole
/// where nothing predicts (one setup, no held-out data).
pub(crate) struct Settled {
    /// The part variants made here (the model's other effects are borrowed).
    pub own: Vec<Box<dyn Effect>>,
    /// For each effect of the model, whether it is `own[k]` or the caller's.
    order: Vec<Result<usize, usize>>,
    /// The families whose parts the campaigns do not decide ([`Undecided`]).
    pub undecided: Vec<Undecided>,
}

impl Settled {
    /// The model as fitted, `in_model`'s effects with the settled families in their place.
    pub fn effects<'a>(&'a self, in_model: &[&'a dyn Effect]) -> Vec<&'a dyn Effect> {
        self.order
            .iter()
            .map(|o| match *o {
                Ok(k) => self.own[k].as_ref(),
                Err(i) => in_model[i],
            })
            .collect()
    }

    /// Nothing settled: the model as given.
    pub fn unchanged(in_model: &[&dyn Effect]) -> Settled {
        Settled {
            own: Vec::new(),
            order: (0..in_model.len()).map(Err).collect(),
            undecided: Vec::new(),
        }
    }

    /// Whether a family was narrowed to some of its parts, or an effect refined.
    pub fn changed(&self) -> bool {
        !self.own.is_empty()
    }
}

/// Settle every family of `in_model` named whole ([`Effect::open_family`]): the part
/// combination with the fewest parts that no combination holding its parts and more (the
/// whole family among them) beats by the evidence a candidate needs (the calibration's
/// F-test with the prediction, not contradicted, a gain that matters), of physical values
/// each; and every effect with refinements to the one that evidence needs, if any
/// ([`refine`]). `level` is that evidence's.
pub(crate) fn settle(
    campaign: &Campaign,
    val: Option<&Validation>,
    in_model: &[&dyn Effect],
    (copts, level): (&calib::Options, f64),
) -> Settled {
    let mut settled = Settled::unchanged(in_model);
    for (i, family) in in_model.iter().enumerate() {
        let chosen = {
            let current = (settled.effects(in_model), i);
            let refinements = family.refinements();
            if !refinements.is_empty() {
                refine(campaign, val, current, refinements, (copts, level))
            } else if let Some(parts) = parts_beside(&current.0, *family) {
                family.with_parts(&parts)
            } else if family.open_family() {
                let (narrowed, undecided) = narrow(campaign, val, current, *family, (copts, level));
                settled.undecided.extend(undecided);
                narrowed
            } else {
                None
            }
        };
        if let Some(effect) = chosen {
            let own = settled.own.len();
            settled.own.push(effect);
            settled.order[i] = Ok(own);
        }
    }
    settled
}

/// The parts of the family `family` named whole refines ([`Effect::beside`]) where that
/// family is in the model with pinned parts: `thermal_lag` lags the parts `thermal` keeps
/// (settled on its own, the lag of the frame came out beside the expansion of the scales).
/// None where it refines nothing, or the family it refines is whole too or absent.
pub(in crate::diagnose) fn parts_beside(
    model: &[&dyn Effect],
    family: &dyn Effect,
) -> Option<Vec<usize>> {
    let of = family.beside().filter(|_| family.open_family())?;
    let refined = model
        .iter()
        .find(|e| crate::effects::family_of(e.name()) == of)?;
    crate::effects::pinned_parts(*refined)
}

/// A part variant of a family, and the same parts of the effect that refines it (if any).
type Variant = (Box<dyn Effect>, Option<Box<dyn Effect>>);

/// The part combination of the family `current[i]` named whole that the evidence needs (see
/// [`settle`]); None where the whole family is it, or nothing predicts. Beside it, where the
/// calibration alone needs a combination of more parts that predicts worse, that one
/// ([`Undecided`]).
fn narrow(
    campaign: &Campaign,
    val: Option<&Validation>,
    (current, i): (Vec<&dyn Effect>, usize),
    family: &dyn Effect,
    (copts, level): (&calib::Options, f64),
) -> (Option<Box<dyn Effect>>, Option<Undecided>) {
    let n = family.parts().len();
    // an effect of the model that refines this family whole takes each variant's parts with
    // it (`thermal_lag` the parts `thermal` is tried with): apart, each absorbs the other
    let follower = current.iter().position(|e| {
        e.open_family() && e.beside() == Some(crate::effects::family_of(family.name()))
    });
    let mut variants: Vec<Variant> = Vec::new();
    for mask in 1..(1usize << n) {
        let parts: Vec<usize> = (0..n).filter(|b| mask & (1 << b) != 0).collect();
        if let Some(v) = family.with_parts(&parts) {
            let along = follower.and_then(|j| current[j].with_parts(&parts));
            variants.push((v, along));
        }
    }
    let scored: Vec<(usize, Scored)> = variants
        .iter()
        .enumerate()
        .filter_map(|(k, (v, along))| {
            let mut with = current.clone();
            with[i] = v.as_ref();
            if let (Some(j), Some(a)) = (follower, along) {
                with[j] = a.as_ref();
            }
            Scored::of(campaign, val, with, copts).map(|p| (k, p))
        })
        .collect();
    // nothing to settle against where the whole family cannot be fitted
    if !scored
        .iter()
        .any(|(k, _)| mask_len(variants[*k].0.name()) == n)
    {
        return (None, None);
    }
    // a variant that fits values no material has stands in for another part (the rods
    // shrinking as the frame grows): it is no settle, however well it predicts
    // and no plausible combination that holds its parts and more beats it, the whole
    // family's not alone: where a campaign hardly separates the three parts, the whole
    // predicts less certainly than two of them (frame and scales expanding: the whole did
    // not beat the scales alone at twice their α, the frame with the scales did)
    let holds = |big: usize, small: usize| {
        let (b, s) = (variants[big].0.as_ref(), variants[small].0.as_ref());
        let held = held_parts(b);
        big != small && held_parts(s).iter().all(|p| held.contains(p))
    };
    let fold = (campaign, copts);
    let adequate = |(k, v): &(usize, Scored)| {
        v.plausible()
            && !scored
                .iter()
                .filter(|(j, big)| holds(*j, *k) && big.plausible())
                .filter_map(|(_, big)| big.parts_over(v, fold))
                .any(|gain| gain.needed(level))
    };
    let Some((k, chosen)) = scored.iter().filter(|e| adequate(e)).min_by(|a, b| {
        let parts = |k: usize| mask_len(variants[k].0.name());
        parts(a.0)
            .cmp(&parts(b.0))
            .then(calib::rms(a.1.held()).total_cmp(&calib::rms(b.1.held())))
    }) else {
        return (None, None);
    };
    // the likeliest combination of more parts that the calibration alone needs over it
    let undecided = scored
        .iter()
        .filter(|(j, big)| holds(*j, *k) && big.plausible())
        .filter_map(|(_, big)| Some((big, big.parts_over(chosen, fold)?)))
        .filter(|(_, gain)| gain.calibration_needs(level))
        .min_by(|a, b| a.0.fit.chi2.total_cmp(&b.0.fit.chi2))
        .and_then(|(big, gain)| {
            // the effects a combination fits in place of the model's whole ones
            let changed = |s: &Scored| -> Vec<String> {
                (s.with.iter())
                    .filter(|e| !current.iter().any(|c| c.name() == e.name()))
                    .map(|e| e.name().to_owned())
                    .collect()
            };
            Some(Undecided {
                settled: changed(chosen),
                needed: changed(big),
                chi2_fall: chosen.fit.chi2 - big.fit.chi2,
                added: chosen.fit.dof - big.fit.dof,
                p_value: gain.p_cal(),
                prediction: gain.prediction()?,
            })
        });
    // the whole family is what the caller has: nothing to own
    let k = *k;
    if mask_len(variants[k].0.name()) == n {
        return (None, undecided);
    }
    drop(scored);
    (Some(variants.swap_remove(k).0), undecided)
}

/// The refinement of the model's effect `current[i]` ([`Effect::refinements`]: a rod with a
/// compliance of its own) the data need: needed over the effect as it is by the evidence a
/// candidate needs, and of those the likeliest: the lowest calibration χ², each a parameter
/// more than the effect (a tracker held out at 40 µm preferred rod 5 to the stiffer rod 3
/// a grid encoder at 1 µm told apart). None where none is needed.
fn refine(
    campaign: &Campaign,
    val: Option<&Validation>,
    (current, i): (Vec<&dyn Effect>, usize),
    mut refinements: Vec<Box<dyn Effect>>,
    (copts, level): (&calib::Options, f64),
) -> Option<Box<dyn Effect>> {
    let plain = Scored::of(campaign, val, current.clone(), copts)?;
    let fold = (campaign, copts);
    let best = refinements
        .iter()
        .enumerate()
        .filter_map(|(k, r)| {
            let mut with = current.clone();
            with[i] = r.as_ref();
            Scored::of(campaign, val, with, copts).map(|s| (k, s))
        })
        .filter(|(_, s)| s.gain_over(&plain, fold).needed(level))
        .min_by(|a, b| a.1.fit.chi2.total_cmp(&b.1.fit.chi2))
        .map(|(k, _)| k)?;
    Some(refinements.swap_remove(best))
}

/// Parts named in a part variant's name (`thermal:rods+frame`: 2).
fn mask_len(name: &str) -> usize {
    name.split_once(':')
        .map_or(usize::MAX, |(_, parts)| parts.split('+').count())
}

/// A model of a settle: its fit (calibration χ², parameters and their covariance), and its
/// prediction errors (held-out with each setup's zero removed, σ; left-out rows, σ, made only
/// where the held-out data cannot tell or there are none).
struct Scored<'a> {
    with: Vec<&'a dyn Effect>,
    fit: Fit,
    rows: usize,
    left_out: std::cell::OnceCell<Option<Vec<f64>>>,
}

/// What a settle's cross-validation needs.
type Fold<'c> = (&'c Campaign, &'c calib::Options);

impl<'a> Scored<'a> {
    /// The model `with` calibrated and its held-out errors; None where it cannot be fitted.
    fn of(
        campaign: &Campaign,
        val: Option<&Validation>,
        with: Vec<&'a dyn Effect>,
        copts: &calib::Options,
    ) -> Option<Scored<'a>> {
        let start = Params::nominal();
        let set = EffectSet::bind(&with, campaign, &start).ok()?;
        let (cal, _) = calib::calibrate(&Request {
            effects: &set,
            leverages: false,
            ..Request::new(campaign, &start, copts)
        })
        .ok()?;
        let rows = cal.residuals.len();
        let fit = finish_with(val, &with, &set, cal).ok()?.fit;
        Some(Scored {
            with,
            fit,
            rows,
            left_out: std::cell::OnceCell::new(),
        })
    }

    /// Whether every parameter fitted lies within what the physics allows
    /// ([`super::gain::implausible`]).
    fn plausible(&self) -> bool {
        super::gain::implausible(&self.fit.effect_params).is_empty()
    }

    /// The held-out errors with each setup's zero removed, each in its own noise (none
    /// without a held-out campaign).
    fn held(&self) -> &[f64] {
        self.fit.held_out.as_ref().map_or(&[], |h| &h.scaled)
    }

    /// The left-out rows (cross-validation by setup), made once.
    fn left_out(&self, (campaign, copts): Fold) -> Option<&[f64]> {
        self.left_out
            .get_or_init(|| {
                cross::predicted_rows(
                    campaign,
                    &cross::Fitted {
                        effects: &self.with,
                        params: &self.fit.params,
                        theta: &self.fit.theta,
                    },
                    copts,
                )
            })
            .as_deref()
    }

    /// What this model gains over the smaller `v` it holds: the nested F-test with the
    /// prediction (held-out where it decides, else the left-out rows, both in σ). Needed
    /// ([`Gain::needed`]) where it beats `v` by the evidence a candidate needs.
    fn gain_over(&self, v: &Scored, fold: Fold) -> Gain {
        let held = Prediction::compared(v.held(), self.held());
        let prediction = match held {
            Some(p) if p.last_word() => Some(p),
            _ => match v.left_out(fold).zip(self.left_out(fold)) {
                Some((a, b)) => Prediction::compared(a, b).map(|p| Prediction {
                    by_setup: true,
                    ..p
                }),
                None => held,
            },
        };
        Gain::of(
            (self.fit.chi2, self.fit.dof),
            (v.fit.chi2, v.fit.dof),
            self.rows,
            prediction,
        )
    }

    /// [`Scored::gain_over`] where this model holds more of a family's parts than `v`: the
    /// parameters of the parts it adds must themselves differ from zero (their Wald test) and
    /// reach a relevant size, as a model's additions must in the search (a frame expanding
    /// at -0.006 ± 0.022 ppm/K beside the scales fitted better only by refitting the rest).
    fn parts_over(&self, v: &Scored, fold: Fold) -> Option<Gain> {
        relevant_beyond(&self.fit, &v.fit).then(|| {
            self.gain_over(v, fold)
                .with_wald(wald_beyond(&self.fit, &v.fit))
        })
    }
}
