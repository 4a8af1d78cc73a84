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
//! The search's files: `entry` (one model, fitted and predicting; the judge's shared
//! work), `pool` (the models tried beside the single candidates), `gain` (the rule a gain
//! must meet), this file (the judgements and the choice); `settle` does the same for a family
//! already in the model and named whole: it keeps the parts that predict.

use super::entry::{added_params, clone_fitted, covers, ranked, rms_of, swapped, Entry, Judge};
use super::gain::{implausible, one_standard_error, Gain, PRACTICAL_SIZE};
use super::pool::Pool;
use crate::diagnose::structure::sparse;
use crate::diagnose::types::{Candidate, EvidenceOf, Fitted, Judged, ModelTrial, Outcome};
use crate::effects;

/// The model the search chose: the effects to add, in the order of their single
/// candidates' ranking.
pub(crate) struct Choice {
    pub added: Vec<String>,
    pub fitted: Fitted,
    /// A dictionary term that explained the residual as well: the model was preferred
    /// because it predicts, which a term cannot.
    pub tied_term: Option<String>,
    /// The part combination of a family of the current model the chosen model fits in place
    /// of the settled one (adding an effect may change the parts a family keeps), if any.
    pub resettled: Option<String>,
}

/// The trials of a round: every fitted candidate alone (`candidates`, with `fits` by name),
/// each part of a family on its own, and pairs; their judgements written into the
/// candidates, the other models returned as trials, and the model chosen.
pub(crate) fn search<'a>(
    judge: &Judge<'a>,
    (candidates, fits): (&mut [Candidate], &[(String, Fitted)]),
    pool: &Pool<'a>,
    structure: &sparse::Structure,
) -> (Vec<ModelTrial>, Option<Choice>) {
    let mut entries: Vec<Entry<'a>> = Vec::new();
    for (i, c) in candidates.iter_mut().enumerate() {
        let Some(effect) = pool.tried.iter().copied().find(|e| e.name() == c.effect) else {
            continue;
        };
        let Some(pos) = fits.iter().position(|(n, _)| *n == c.effect) else {
            continue;
        };
        let fitted = clone_fitted(&fits[pos].1);
        let mut entry = judge.entry((vec![effect], None), fitted, Some(i));
        if entry.candidate.is_some() && c.prediction.is_some_and(|p| !p.decides()) {
            c.cross_validated = entry.prediction.filter(|p| p.by_setup);
        }
        entry.relevant = c.relevant;
        entries.push(entry);
    }
    let singles = entries.len();
    judge.add_parts(&mut entries, pool.variants);
    judge.add_followed(&mut entries, pool.followers);
    judge.add_pairs(&mut entries, candidates, singles);
    judge.add_swaps(&mut entries, pool.swaps, singles);
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
            resettled: swapped(e).map(str::to_owned),
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
            wald_p: e.wald_p,
            f_p: e.f_p,
            chi2_per_dof_after: e.fitted.fit.chi2_per_dof,
            prediction: e.prediction,
            params: added_params(&e.fitted.fit.effect_params, &e.added),
            judged: e.judged,
        })
        .collect();
    (trials, choice)
}

impl Judge<'_> {
    /// The judgement of one entry against the current model: the evidence of both
    /// campaigns, its size, its values.
    fn assess(&self, e: &mut Entry) {
        let base = &self.base.fit;
        let gain = Gain::of(
            (e.fitted.fit.chi2, e.fitted.fit.dof),
            (base.chi2, base.dof),
            self.base.rows.len(),
            e.prediction,
        )
        .with_wald(e.wald_p);
        // a model that fits a family of the current model with other parts gains by those
        // parts too, which its prediction cannot tell from the effect added: the calibration
        // must need it by itself (an encoder scale of -9 ± 8 ppm, F-test p = 5.4e-3, was
        // named on the prediction the frame's expansion made beside the scales'; another
        // whose fit was worse than the current model's, F < 0, on the prediction alone)
        let evidence_p = match e.swap {
            Some(_) => gain.evidence().max(gain.p_cal()),
            None => gain.evidence(),
        };
        let size = gain.size();
        let rows = self.base.rows.len().max(1) as f64;
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
            evidence_of: EvidenceOf::of(e.prediction.as_ref()),
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
                swapped(e) == swapped(&entries[k])
                    && other.len() == rest.len()
                    && rest.iter().all(|r| other.contains(r))
            });
            // a member without which the values are unphysical earns its place: the rest
            // fit it only by absorbing it (a thermometer 16 min behind rods and frame that a
            // tracker and self-calibration hardly tell apart: the expansion alone at 70 and
            // 55 ppm/K predicted as well as with its lag at 20 ± 14 and 16 ± 14)
            without.is_none_or(|w| w.unphysical() || judge.beats(&entries[k], w))
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
        // a larger model of unphysical values leaves nothing out that earns a place: it
        // absorbs something else
        let incomplete = (0..entries.len())
            .filter(|&j| j != k && covers(&entries[j], &entries[k]))
            .filter(|&j| !entries[j].unphysical())
            .any(|j| judge.beats(&entries[j], &entries[k]));
        if incomplete {
            entries[k].judged.outcome = Outcome::Incomplete;
        }
    }
}

/// The model named: among the eligible, the simplest within one standard error of the best
/// predicting (of those as simple, the one that fits the calibration best); one that a single
/// dictionary term explains as well must leave no structure behind. Returns the entry and the
/// term it was preferred to.
fn choose(
    judge: &Judge,
    entries: &mut [Entry],
    structure: &sparse::Structure,
) -> Option<(usize, Option<String>)> {
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
                // as simple, and predicting alike: the better fit of the calibration (the
                // same weights, as many parameters) decides, not the prediction's noise
                let chi2 = |k: usize| entries[k].fitted.fit.chi2;
                entries[a]
                    .complexity()
                    .cmp(&entries[b].complexity())
                    .then(chi2(a).total_cmp(&chi2(b)))
            })?;
        let e = &entries[pick];
        let mut tied = None;
        if judge.term_rivals(&e.fitted.fit, &judge.base.fit, structure) {
            let clean = e.structure(judge.campaign).p_value >= judge.structure_level;
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
