//! The model chosen as a whole. A candidate judged alone can fail two ways: a family fitted
//! whole where the campaign cannot separate its parts (thermal's rods, frame and scales from
//! a tracker and self-calibration alone come out as numbers no material has), and two effects
//! that only work together (thermal and the preload's deflection each absorb part of the
//! other, and neither predicts better alone). So the search fits the candidates that stand
//! out, each part of a family on its own and pairs, judges each by the evidence of both
//! campaigns, by whether it matters and whether its values are physical, and chooses the
//! model that predicts held-out data best (else the setups cross-validation leaves out),
//! taking the simplest among those within one standard error of the best.
//!
//! [`settle`] does the same for a family already in the model and named whole: it keeps the
//! parts that predict.

use super::cross;
use super::held_out::{Model1, Validation};
use super::sparse;
use super::trials::{finish_with, warm_theta, SCREEN_P};
use super::types::{Candidate, FitError, Fitted, Judged, ModelTrial, Outcome, Prediction};
use super::RELEVANT_FRACTION;
use crate::calib::{self, EffectEstimate, Request};
use crate::campaign::Campaign;
use crate::effects::{self, Effect, EffectSet};
use crate::params::Params;
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

/// A family's part combinations a settle compares (thermal's three parts: seven), the
/// Bonferroni count of its evidence.
pub const PART_COMBINATIONS: f64 = 7.0;

/// The best contenders (by BIC gain) are paired among themselves; the best also with every
/// other candidate.
const PAIRED: usize = 3;

/// What every judgement of a search shares: the current model, its fit and its predictions.
pub(crate) struct Judge<'a> {
    pub campaign: &'a Campaign,
    pub val: Option<&'a Validation<'a>>,
    pub in_model: &'a [&'a dyn Effect],
    pub base: &'a Fitted,
    pub copts: &'a calib::Options,
    /// Level of the evidence (Bonferroni over the candidates).
    pub level: f64,
    /// Level of the structure tests (a term that explains as much as an effect).
    pub structure_level: f64,
    /// The held-out floor with each setup's zero removed, mm: the noise a prediction's
    /// explained part is measured in (left-out rows are in σ already).
    pub floor_mm: Option<f64>,
    /// The current model's left-out rows (cross-validation by setup), made once when first
    /// needed.
    pub base_cv: std::cell::OnceCell<Option<Vec<f64>>>,
}

/// One model of the search: the current model with `added`, its fit and how it predicts.
struct Entry<'a> {
    added: Vec<&'a dyn Effect>,
    /// A family of the current model with other parts, in place of the settled one (the
    /// parts a family keeps may change with the effect added).
    swap: Option<&'a dyn Effect>,
    fitted: Fitted,
    /// Held-out errors with each setup's zero removed (mm), where there are held-out data.
    held: Option<Vec<f64>>,
    /// Left-out rows (σ), where the held-out data do not decide against the current model.
    left_out: Option<Vec<f64>>,
    prediction: Option<Prediction>,
    p_value: f64,
    f_statistic: f64,
    k: f64,
    judged: Judged,
    relevant: bool,
    /// Index of the single candidate this entry is (None: a part subset or a pair).
    candidate: Option<usize>,
}

impl Entry<'_> {
    fn names(&self) -> Vec<String> {
        self.added.iter().map(|e| e.name().to_owned()).collect()
    }

    /// How simple it is: effects added, then parameters.
    fn complexity(&self) -> (usize, usize) {
        let params = self
            .fitted
            .fit
            .effect_params
            .iter()
            .filter(|p| self.added.iter().any(|e| e.name() == p.effect))
            .count();
        (self.added.len(), params)
    }

    /// Whether it could be named.
    fn eligible(&self) -> bool {
        matches!(self.judged.outcome, Outcome::Outpredicted)
    }
}

/// The model the search chose: the effects to add, in the order of their single
/// candidates' ranking.
pub(crate) struct Choice {
    pub added: Vec<String>,
    pub fitted: Fitted,
    /// A dictionary term that explained the residual as well: the model was preferred
    /// because it predicts, which a term cannot.
    pub tied_term: Option<String>,
}

/// The trials of a round: every fitted candidate alone (`candidates`, with `fits` by name),
/// each part of a family on its own, and pairs; their judgements written into the
/// candidates, the other models returned as trials, and the model chosen.
pub(crate) fn search<'a>(
    judge: &Judge<'a>,
    (candidates, fits): (&mut [Candidate], &[(String, Fitted)]),
    (tried, variants, swaps): (
        &[&'a dyn Effect],
        &'a [Box<dyn Effect>],
        &'a [Box<dyn Effect>],
    ),
    structure: &sparse::Structure,
) -> (Vec<ModelTrial>, Option<Choice>) {
    let mut entries: Vec<Entry<'a>> = Vec::new();
    for (i, c) in candidates.iter_mut().enumerate() {
        let Some(effect) = tried.iter().copied().find(|e| e.name() == c.effect) else {
            continue;
        };
        let Some(pos) = fits.iter().position(|(n, _)| *n == c.effect) else {
            continue;
        };
        let fitted = clone_fitted(&fits[pos].1);
        let mut entry = judge.entry((vec![effect], None), fitted, Some(i));
        if entry.candidate.is_some() && c.prediction.is_some_and(|p| !p.better && !p.worse) {
            c.cross_validated = entry.prediction.filter(|p| p.by_setup);
        }
        entry.relevant = c.relevant;
        entries.push(entry);
    }
    let singles = entries.len();
    judge.add_parts(&mut entries, variants);
    judge.add_pairs(&mut entries, candidates, singles);
    judge.add_swaps(&mut entries, swaps, singles);
    for e in &mut entries {
        judge.assess(e);
    }
    each_earns_its_place(judge, &mut entries);
    nothing_left_out_earns(judge, &mut entries);
    let chosen = choose(judge, &mut entries, structure);
    for e in &entries {
        if let Some(i) = e.candidate {
            candidates[i].judged = e.judged.clone();
        }
    }
    let choice = chosen.map(|(k, tied_term)| {
        let e = &entries[k];
        let mut added = e.names();
        // the single candidates' ranking orders the names: the strongest first
        let rank = |n: &str| {
            candidates
                .iter()
                .position(|c| effects::family_of(&c.effect) == effects::family_of(n))
                .unwrap_or(usize::MAX)
        };
        added.sort_by_key(|n| rank(n));
        Choice {
            added,
            fitted: clone_fitted(&e.fitted),
            tied_term,
        }
    });
    let trials = entries
        .into_iter()
        .filter(|e| e.candidate.is_none())
        .map(|e| ModelTrial {
            added: e.names(),
            instead: e.swap.map(|s| s.name().to_owned()),
            k: e.k,
            f_statistic: e.f_statistic,
            p_value: e.p_value,
            chi2_per_dof_after: e.fitted.fit.chi2_per_dof,
            prediction: e.prediction,
            params: added_params(&e.fitted.fit.effect_params, &e.added),
            judged: e.judged,
        })
        .collect();
    (trials, choice)
}

fn clone_fitted(f: &Fitted) -> Fitted {
    Fitted {
        rows: f.rows.clone(),
        fit: f.fit.clone(),
    }
}

/// The parameters of the effects `added` among a fit's.
fn added_params(all: &[EffectEstimate], added: &[&dyn Effect]) -> Vec<EffectEstimate> {
    all.iter()
        .filter(|p| added.iter().any(|e| e.name() == p.effect))
        .cloned()
        .collect()
}

impl<'j> Judge<'j> {
    /// A model's entry: its nested test against the current model and its prediction.
    fn entry<'a>(
        &self,
        (added, swap): (Vec<&'a dyn Effect>, Option<&'a dyn Effect>),
        fitted: Fitted,
        candidate: Option<usize>,
    ) -> Entry<'a> {
        let base = &self.base.fit;
        let k = (base.dof - fitted.fit.dof).max(0.0);
        let dchi2 = base.chi2 - fitted.fit.chi2;
        let f_statistic = if k > 0.5 {
            (dchi2 / k) / (fitted.fit.chi2 / fitted.fit.dof)
        } else {
            0.0
        };
        let p_value = if k > 0.5 {
            stats::f_upper_tail(f_statistic, k, fitted.fit.dof)
        } else {
            1.0
        };
        let relevant = fitted
            .fit
            .effect_params
            .iter()
            .filter(|p| added.iter().any(|e| e.name() == p.effect))
            .filter(|p| p.identified && p.prior > 0.0)
            .any(|p| p.value.abs() >= RELEVANT_FRACTION * p.prior);
        let mut entry = Entry {
            added,
            swap,
            fitted,
            held: None,
            left_out: None,
            prediction: None,
            p_value,
            f_statistic,
            k,
            judged: Judged::default(),
            relevant,
            candidate,
        };
        self.predict(&mut entry);
        entry
    }

    /// The entry's prediction against the current model's: held-out data where they decide
    /// (better, or clearly worse), else the setups cross-validation leaves out, for a model
    /// that may matter.
    fn predict(&self, e: &mut Entry) {
        let held = self
            .val
            .and_then(|_| Prediction::of(&self.base.fit.val_errors, &e.fitted.fit.val_errors));
        if held.is_some() {
            e.held = Some(e.fitted.fit.val_errors.clone());
        }
        e.prediction = held;
        if held.is_some_and(|p| p.better || p.worse) {
            return;
        }
        // left-out rows only where the calibration itself says it may matter: on a hundred
        // thousand rows a fold's refit is costly, and an addition whose signature in the rows
        // is a tenth of their noise cannot predict them better by a fifth
        let rows = self.base.rows.len().max(1) as f64;
        let cal_size = ((self.base.fit.chi2 - e.fitted.fit.chi2).max(0.0) / rows).sqrt();
        if e.p_value >= SCREEN_P || cal_size < 0.5 * PRACTICAL_SIZE {
            return;
        }
        let Some(rows) = self.left_out((&e.added, e.swap), &e.fitted) else {
            return;
        };
        let base = self.base_cv.get_or_init(|| {
            cross::predicted_rows(
                self.campaign,
                &cross::Fitted {
                    effects: self.in_model,
                    params: &self.base.fit.params,
                    theta: &self.base.fit.theta,
                },
                self.copts,
            )
        });
        if let Some(b) = base {
            e.prediction = Prediction::compared(b, &rows).map(|p| Prediction {
                by_setup: true,
                ..p
            });
            e.left_out = Some(rows);
        }
    }

    /// The left-out rows of the model with `added` (cross-validation by setup).
    fn left_out(
        &self,
        (added, swap): (&[&dyn Effect], Option<&dyn Effect>),
        fitted: &Fitted,
    ) -> Option<Vec<f64>> {
        let with = self.model_of(added, swap);
        cross::predicted_rows(
            self.campaign,
            &cross::Fitted {
                effects: &with,
                params: &fitted.fit.params,
                theta: &fitted.fit.theta,
            },
            self.copts,
        )
    }

    /// The current model with `added`, and `swap` in place of its member of the same family.
    fn model_of<'e>(
        &self,
        added: &[&'e dyn Effect],
        swap: Option<&'e dyn Effect>,
    ) -> Vec<&'e dyn Effect>
    where
        'j: 'e,
    {
        let mut with: Vec<&dyn Effect> = self
            .in_model
            .iter()
            .map(|e| match swap {
                Some(s) if effects::family_of(s.name()) == effects::family_of(e.name()) => s,
                _ => *e,
            })
            .collect();
        with.extend(added.iter().copied());
        with
    }

    /// The current model with `added` (and `swap`), fitted from the current model's minimum
    /// (the added effects' parameters from `warm` where it has them).
    fn fit(
        &self,
        (added, swap): (&[&dyn Effect], Option<&dyn Effect>),
        warm: &[&Fitted],
    ) -> Result<Fitted, FitError> {
        let with = self.model_of(added, swap);
        let start = Params::nominal();
        let set = EffectSet::bind(&with, self.campaign, &start)?;
        let mut theta = warm_theta(&set, &self.base.fit);
        for w in warm {
            for (t, v) in theta.iter_mut().zip(warm_theta(&set, &w.fit)) {
                if *t == 0.0 {
                    *t = v;
                }
            }
        }
        let (cal, _) = calib::calibrate(&Request {
            effects: &set,
            warm: Some(calib::WarmStart {
                params: &self.base.fit.params,
                theta: &theta,
                screen: false,
            }),
            ..Request::new(self.campaign, &start, self.copts)
        })?;
        finish_with(self.val, &with, &set, cal, self.copts)
    }

    /// Each part of a family that stands out, on its own and in every smaller combination
    /// (`variants`: [`part_variants`]): the campaign may separate some parts and not others.
    fn add_parts<'a>(&self, entries: &mut Vec<Entry<'a>>, variants: &'a [Box<dyn Effect>]) {
        let families: Vec<usize> = (0..entries.len())
            .filter(|&k| entries[k].added.len() == 1)
            .filter(|&k| entries[k].added[0].parts().len() > 1)
            .filter(|&k| entries[k].p_value < SCREEN_P)
            .collect();
        for k in families {
            let family = entries[k].added[0].name().to_owned();
            for v in variants
                .iter()
                .filter(|v| effects::family_of(v.name()) == family)
            {
                let warm = [&entries[k].fitted];
                if let Ok(fitted) = self.fit((&[v.as_ref()], None), &warm) {
                    let e = self.entry((vec![v.as_ref()], None), fitted, None);
                    entries.push(e);
                }
            }
        }
    }

    /// Pairs: the best contenders among themselves, and the best with every other
    /// candidate (an effect that only works with another may not stand out alone). A family
    /// takes part by its best-predicting variant.
    fn add_pairs<'a>(
        &self,
        entries: &mut Vec<Entry<'a>>,
        candidates: &[Candidate],
        singles: usize,
    ) {
        let mut contenders: Vec<usize> = (0..singles)
            .filter(|&k| entries[k].p_value < SCREEN_P && entries[k].relevant)
            .collect();
        contenders.sort_by(|&a, &b| {
            let bic = |k: usize| entries[k].candidate.map_or(0.0, |i| candidates[i].bic_gain);
            bic(b).total_cmp(&bic(a))
        });
        // a family takes part whole and by each of its parts alone: which part works with
        // the other effect is what the pair finds out (alone, each absorbs part of the other)
        let variants_of = |k: usize, entries: &[Entry<'a>]| -> Vec<usize> {
            let family = effects::family_of(entries[k].added[0].name());
            (0..entries.len())
                .filter(|&j| j == k || entries[j].candidate.is_none())
                .filter(|&j| entries[j].added.len() == 1)
                .filter(|&j| effects::family_of(entries[j].added[0].name()) == family)
                .filter(|&j| j == k || !entries[j].added[0].name().contains('+'))
                .collect()
        };
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        let top: Vec<usize> = contenders.iter().copied().take(PAIRED).collect();
        for (n, &a) in top.iter().enumerate() {
            for &b in &top[n + 1..] {
                pairs.push((a, b));
            }
        }
        if let Some(&first) = top.first() {
            for b in (0..singles).filter(|b| *b != first && !top.contains(b)) {
                pairs.push((first, b));
            }
        }
        let pairs: Vec<(usize, usize)> = pairs
            .into_iter()
            .flat_map(|(a, b)| {
                let vb = variants_of(b, entries);
                variants_of(a, entries)
                    .into_iter()
                    .flat_map(move |x| vb.clone().into_iter().map(move |y| (x, y)))
            })
            .collect();
        for (a, b) in pairs {
            let added = vec![entries[a].added[0], entries[b].added[0]];
            let warm = [&entries[a].fitted, &entries[b].fitted];
            if let Ok(fitted) = self.fit((&added, None), &warm) {
                let e = self.entry((added, None), fitted, None);
                entries.push(e);
            }
        }
    }

    /// The best contenders with each other part combination of a family of the current
    /// model (`swaps`: its variants): adding an effect may change the parts a family keeps
    /// (a guide's bow absorbed by the frame's expansion until the bow is in the model).
    fn add_swaps<'a>(
        &self,
        entries: &mut Vec<Entry<'a>>,
        swaps: &'a [Box<dyn Effect>],
        singles: usize,
    ) where
        'j: 'a,
    {
        let settled: Vec<&str> = self.in_model.iter().map(|e| e.name()).collect();
        let mut contenders: Vec<usize> = (0..singles)
            .filter(|&k| entries[k].p_value < SCREEN_P && entries[k].relevant)
            .collect();
        contenders.sort_by(|&a, &b| entries[a].p_value.total_cmp(&entries[b].p_value));
        contenders.truncate(PAIRED);
        for k in contenders {
            for v in swaps.iter().filter(|v| !settled.contains(&v.name())) {
                let added = vec![entries[k].added[0]];
                let warm = [&entries[k].fitted];
                if let Ok(fitted) = self.fit((&added, Some(v.as_ref())), &warm) {
                    let e = self.entry((added, Some(v.as_ref())), fitted, None);
                    entries.push(e);
                }
            }
        }
    }

    /// Whether model `big` beats model `small` (which it holds) by the evidence a candidate
    /// needs: the nested F-test between the two with their prediction (held-out where it
    /// decides, else left-out rows) combined below the level, not contradicted, better, by a
    /// gain that matters.
    fn beats(&self, big: &Entry, small: &Entry) -> bool {
        let (b, s) = (&big.fitted.fit, &small.fitted.fit);
        let k = s.dof - b.dof;
        if k < 0.5 {
            return false;
        }
        let f = ((s.chi2 - b.chi2).max(0.0) / k) / (b.chi2 / b.dof);
        let p_cal = stats::f_upper_tail(f, k, b.dof);
        let (evidence, size, better, worse) = match between(small, big) {
            Some(p) => {
                let unit = if p.by_setup {
                    1.0
                } else {
                    self.floor_mm.unwrap_or(1.0)
                };
                (
                    stats::fisher_combined(&[p_cal, p.p_better()]),
                    p.explained() / unit,
                    p.better,
                    p.worse,
                )
            }
            None => {
                let rows = self.base.rows.len().max(1) as f64;
                (
                    p_cal,
                    ((s.chi2 - b.chi2).max(0.0) / rows).sqrt(),
                    true,
                    false,
                )
            }
        };
        evidence < self.level && better && !worse && size >= PRACTICAL_SIZE
    }

    /// The judgement of one entry against the current model: the evidence of both
    /// campaigns, its size, its values.
    fn assess(&self, e: &mut Entry) {
        let p_pred = e.prediction.map(|p| p.p_better());
        let evidence_p = match p_pred {
            Some(p) => stats::fisher_combined(&[e.p_value, p]),
            None => e.p_value,
        };
        let rows = self.base.rows.len().max(1) as f64;
        let size = match e.prediction {
            Some(p) if p.by_setup || self.floor_mm.is_none() => p.explained(),
            Some(p) => p.explained() / (self.floor_mm.unwrap_or(1.0) * 1e3),
            None => ((self.base.fit.chi2 - e.fitted.fit.chi2).max(0.0) / rows).sqrt(),
        };
        let implausible = implausible(&added_params(&e.fitted.fit.effect_params, &e.added));
        let better = e.prediction.map_or(e.f_statistic > rows.ln(), |p| p.better);
        let outcome = if evidence_p >= self.level {
            Outcome::NotSignificant
        } else if e.prediction.is_some_and(|p| p.worse) {
            Outcome::Contradicted
        } else if !better {
            Outcome::NoBetter
        } else if !implausible.is_empty() {
            Outcome::Implausible
        } else if size < PRACTICAL_SIZE {
            Outcome::TooSmall
        } else if !e.relevant {
            Outcome::Irrelevant
        } else {
            // eligible: the choice below names it or says why not
            Outcome::Outpredicted
        };
        e.judged = Judged {
            evidence_p,
            size: Some(size),
            matters: size >= PRACTICAL_SIZE,
            implausible,
            outcome,
        };
    }
}

/// A model of several effects is named only where it beats the model without each of them
/// ([`Judge::beats`]): every effect earns its place.
fn each_earns_its_place(judge: &Judge, entries: &mut [Entry]) {
    for k in 0..entries.len() {
        if entries[k].added.len() < 2 || !entries[k].eligible() {
            continue;
        }
        let names = entries[k].names();
        let earns = names.iter().all(|member| {
            let rest: Vec<&String> = names.iter().filter(|n| *n != member).collect();
            let without = entries.iter().find(|e| {
                let other = e.names();
                e.swap.map(|s| s.name()) == entries[k].swap.map(|s| s.name())
                    && other.len() == rest.len()
                    && rest.iter().all(|r| other.contains(r))
            });
            without.is_none_or(|w| judge.beats(&entries[k], w))
        });
        if !earns {
            entries[k].judged.outcome = Outcome::MemberAddsNothing;
        }
    }
}

/// A model is named only where no model that holds it and more (another part of a family,
/// another effect) beats it ([`Judge::beats`]): nothing it leaves out earns a place (a
/// family's part that the calibration needs and the held-out instrument cannot see).
fn nothing_left_out_earns(judge: &Judge, entries: &mut [Entry]) {
    for k in 0..entries.len() {
        if !entries[k].eligible() {
            continue;
        }
        let incomplete = (0..entries.len())
            .filter(|&j| j != k && covers(&entries[j], &entries[k]))
            .any(|j| judge.beats(&entries[j], &entries[k]));
        if incomplete {
            entries[k].judged.outcome = Outcome::Incomplete;
        }
    }
}

/// The parts of an effect in a model: those it pins (`thermal:rods`), every part of a family
/// named whole, none for an effect of one piece.
fn parts_of(e: &dyn Effect) -> Vec<String> {
    match e.name().split_once(':') {
        Some((_, parts)) => parts.split('+').map(str::to_owned).collect(),
        None => e.parts().iter().map(|p| (*p).to_owned()).collect(),
    }
}

/// Whether model `big` holds everything of `small` and more: every effect of `small` (or its
/// family with at least its parts), with the same family swapped in.
fn covers(big: &Entry, small: &Entry) -> bool {
    if big.swap.map(|s| s.name()) != small.swap.map(|s| s.name()) {
        return false;
    }
    let holds = |e: &&dyn Effect| {
        big.added.iter().any(|b| {
            effects::family_of(b.name()) == effects::family_of(e.name()) && {
                let have = parts_of(*b);
                parts_of(*e).iter().all(|p| have.contains(p))
            }
        })
    };
    let size = |m: &Entry| -> usize { m.added.iter().map(|e| 1 + parts_of(*e).len()).sum() };
    small.added.iter().all(holds) && size(big) > size(small)
}

/// Every proper part combination of each family among `effects` named whole (thermal: rods,
/// frame, scales, and the pairs of them): what the search tries where a family stands out;
/// with `whole`, the whole family too (the variants of a family in the current model).
pub(crate) fn part_variants(effects: &[&dyn Effect], whole: bool) -> Vec<Box<dyn Effect>> {
    let mut out = Vec::new();
    for family in effects.iter().filter(|e| e.open_family()) {
        let n = family.parts().len();
        let last = if whole {
            1usize << n
        } else {
            (1usize << n) - 1
        };
        for mask in 1..last {
            let parts: Vec<usize> = (0..n).filter(|b| mask & (1 << b) != 0).collect();
            out.extend(family.with_parts(&parts));
        }
    }
    out
}

/// The errors models are ranked by: held-out where there are held-out data, else left-out
/// rows.
fn ranked<'e>(e: &'e Entry) -> Option<&'e [f64]> {
    e.held.as_deref().or(e.left_out.as_deref())
}

fn rms_of(e: &Entry) -> f64 {
    ranked(e).map_or(f64::INFINITY, calib::rms)
}

/// Model `b` against model `a`: on the held-out data where they decide between the two,
/// else on the left-out rows where both have them, else the held-out tie.
fn between(a: &Entry, b: &Entry) -> Option<Prediction> {
    let held = a
        .held
        .as_deref()
        .zip(b.held.as_deref())
        .and_then(|(x, y)| Prediction::compared(x, y));
    if held.is_some_and(|p| p.better || p.worse) {
        return held;
    }
    a.left_out
        .as_deref()
        .zip(b.left_out.as_deref())
        .and_then(|(x, y)| Prediction::compared(x, y))
        .map(|p| Prediction {
            by_setup: true,
            ..p
        })
        .or(held)
}

/// The parameters fitted clearly outside the values the physics allows.
fn implausible(params: &[EffectEstimate]) -> Vec<String> {
    params
        .iter()
        .filter(|p| p.identified)
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
fn sig(v: f64) -> String {
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

/// The model named: among the eligible, the simplest within one standard error of the best
/// predicting; one that a single dictionary term explains as well must leave no structure
/// behind. Returns the entry and the term it was preferred to.
fn choose(
    judge: &Judge,
    entries: &mut [Entry],
    structure: &sparse::Structure,
) -> Option<(usize, Option<String>)> {
    let n_rows = judge.base.rows.len() as f64;
    let term_bic = structure.explained_chi2 - n_rows.ln();
    loop {
        let eligible: Vec<usize> = (0..entries.len())
            .filter(|&k| entries[k].eligible())
            .collect();
        let best = *eligible
            .iter()
            .min_by(|&&a, &&b| rms_of(&entries[a]).total_cmp(&rms_of(&entries[b])))?;
        let spread = ranked(&entries[best]).map_or(0.0, one_standard_error);
        let close: Vec<bool> = (0..entries.len())
            .map(|k| k == best || rms_of(&entries[k]) - rms_of(&entries[best]) <= spread)
            .collect();
        let pick = eligible
            .iter()
            .copied()
            .filter(|&k| close[k])
            .min_by(|&a, &b| {
                entries[a]
                    .complexity()
                    .cmp(&entries[b].complexity())
                    .then(rms_of(&entries[a]).total_cmp(&rms_of(&entries[b])))
            })?;
        let e = &entries[pick];
        let gain = judge.base.fit.chi2 - e.fitted.fit.chi2 - e.k * n_rows.ln();
        let mut tied = None;
        if gain <= term_bic {
            let clean =
                sparse::structure(judge.campaign, &e.fitted.rows).p_value >= judge.structure_level;
            if !clean {
                entries[pick].judged.outcome = Outcome::OutdoneByTerm;
                continue;
            }
            tied = structure.pointer.as_ref().map(|p| p.feature.clone());
        }
        for &k in &eligible {
            entries[k].judged.outcome = if k == pick {
                Outcome::Named
            } else if close[k] {
                Outcome::SimplerNamed
            } else {
                Outcome::Outpredicted
            };
        }
        return Some((pick, tied));
    }
}

/// The current model with its families named whole settled: each keeps the parts (and
/// combination of parts) that predicts held-out data best, else the setups cross-validation
/// leaves out, the simplest within one standard error of the best. A family stays whole
/// where nothing predicts (one setup, no held-out data).
pub(crate) struct Settled {
    /// The part variants made here (the model's other effects are borrowed).
    pub own: Vec<Box<dyn Effect>>,
    /// For each effect of the model, whether it is `own[k]` or the caller's.
    order: Vec<Result<usize, usize>>,
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
        }
    }

    /// Whether a family was narrowed to some of its parts.
    pub fn changed(&self) -> bool {
        !self.own.is_empty()
    }
}

/// Settle every family of `in_model` named whole ([`Effect::open_family`]): the part
/// combination with the fewest parts that the whole family does not beat by the evidence a
/// candidate needs (the calibration's F-test with the prediction, not contradicted, a gain
/// that matters); `level` is that evidence's.
pub(crate) fn settle(
    campaign: &Campaign,
    val: Option<&Validation>,
    in_model: &[&dyn Effect],
    (copts, level): (&calib::Options, f64),
) -> Settled {
    let mut settled = Settled::unchanged(in_model);
    for (i, family) in in_model.iter().enumerate() {
        if !family.open_family() {
            continue;
        }
        let n = family.parts().len();
        let mut variants: Vec<Box<dyn Effect>> = Vec::new();
        for mask in 1..(1usize << n) {
            let parts: Vec<usize> = (0..n).filter(|b| mask & (1 << b) != 0).collect();
            variants.extend(family.with_parts(&parts));
        }
        let current = settled.effects(in_model);
        let scored: Vec<(usize, Scored)> = variants
            .iter()
            .enumerate()
            .filter_map(|(k, v)| {
                let mut with = current.clone();
                with[i] = v.as_ref();
                Scored::of(campaign, val, with, copts).map(|p| (k, p))
            })
            .collect();
        let Some(whole) = scored
            .iter()
            .find(|(k, _)| mask_len(variants[*k].name()) == n)
        else {
            continue;
        };
        let floor = val.map(|v| calib::rms(&v.relative_sigma));
        let adequate = |v: &Scored| !whole.1.needed_over(v, (campaign, copts), (level, floor));
        let Some(k) = scored
            .iter()
            .filter(|(_, v)| adequate(v))
            .min_by(|a, b| {
                let parts = |k: usize| mask_len(variants[k].name());
                parts(a.0)
                    .cmp(&parts(b.0))
                    .then(calib::rms(&a.1.held).total_cmp(&calib::rms(&b.1.held)))
            })
            .map(|(k, _)| *k)
        else {
            continue;
        };
        // the whole family is what the caller has: nothing to own
        if mask_len(variants[k].name()) == n {
            continue;
        }
        let own = settled.own.len();
        settled.own.push(variants.swap_remove(k));
        settled.order[i] = Ok(own);
    }
    settled
}

/// Parts named in a part variant's name (`thermal:rods+frame`: 2).
fn mask_len(name: &str) -> usize {
    name.split_once(':')
        .map_or(usize::MAX, |(_, parts)| parts.split('+').count())
}

/// A model of a settle: its calibration χ², and its prediction errors (held-out with each
/// setup's zero removed, mm; left-out rows, σ, made only where the held-out data cannot tell
/// or there are none).
struct Scored<'a> {
    with: Vec<&'a dyn Effect>,
    params: Params,
    theta: Vec<f64>,
    chi2: f64,
    dof: f64,
    rows: usize,
    held: Vec<f64>,
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
            ..Request::new(campaign, &start, copts)
        })
        .ok()?;
        let chi2: f64 = cal
            .residuals
            .iter()
            .map(|r| (r.value / r.sigma).powi(2))
            .sum();
        let rows = cal.residuals.len();
        let held = match val {
            Some(v) => {
                let errors = Model1 {
                    effects: &with,
                    cal_set: &set,
                    cal: &cal,
                }
                .errors(v)
                .ok()?;
                v.relative(&errors)
            }
            None => Vec::new(),
        };
        Some(Scored {
            with,
            params: cal.params,
            theta: cal.theta,
            chi2,
            dof: (rows as f64 - cal.dof_model).max(1.0),
            rows,
            held,
            left_out: std::cell::OnceCell::new(),
        })
    }

    /// The left-out rows (cross-validation by setup), made once.
    fn left_out(&self, (campaign, copts): Fold) -> Option<&[f64]> {
        self.left_out
            .get_or_init(|| {
                cross::predicted_rows(
                    campaign,
                    &cross::Fitted {
                        effects: &self.with,
                        params: &self.params,
                        theta: &self.theta,
                    },
                    copts,
                )
            })
            .as_deref()
    }

    /// Whether this model (the whole family) beats the smaller `v` by the evidence a
    /// candidate needs: the nested F-test with the prediction (held-out where it decides,
    /// else the left-out rows), not contradicted, a gain that matters (`floor`: the held-out
    /// noise, mm).
    fn needed_over(&self, v: &Scored, fold: Fold, (level, floor): (f64, Option<f64>)) -> bool {
        let k = v.dof - self.dof;
        if k < 0.5 {
            return false;
        }
        let f = ((v.chi2 - self.chi2).max(0.0) / k) / (self.chi2 / self.dof);
        let p_cal = stats::f_upper_tail(f, k, self.dof);
        let held = Prediction::compared(&v.held, &self.held);
        let (prediction, unit) = match held {
            Some(p) if p.better || p.worse => (Some(p), floor.unwrap_or(1.0)),
            _ => match v.left_out(fold).zip(self.left_out(fold)) {
                Some((a, b)) => (Prediction::compared(a, b), 1.0),
                None => (held, floor.unwrap_or(1.0)),
            },
        };
        let (evidence, size, better, worse) = match prediction {
            Some(p) => (
                stats::fisher_combined(&[p_cal, p.p_better()]),
                p.explained() / unit,
                p.better,
                p.worse,
            ),
            None => (
                p_cal,
                ((v.chi2 - self.chi2).max(0.0) / self.rows.max(1) as f64).sqrt(),
                true,
                false,
            ),
        };
        evidence < level && better && !worse && size >= PRACTICAL_SIZE
    }
}
