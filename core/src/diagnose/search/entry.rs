//! One model of a search ([`Entry`]): the current model with effects added (and a family of
//! it swapped for other parts), fitted, tested against the current model and predicting; and
//! what every judgement of a search shares ([`Judge`]): fitting such a model, its prediction
//! (held-out data where they decide, else the setups cross-validation leaves out), and
//! whether one model beats another it holds.

use super::cross;
use super::gain::{relevant, relevant_beyond, wald_beyond, wald_p, Gain, Nested, PRACTICAL_SIZE};
use super::trials::{finish_with, warm_theta_among, SCREEN_P};
use crate::calib::{self, EffectEstimate, Request};
use crate::campaign::Campaign;
use crate::diagnose::held_out::validation::Validation;
use crate::diagnose::structure::sparse;
use crate::diagnose::types::{FitError, Fitted, Judged, Outcome, Prediction};
use crate::effects::{self, Effect, EffectSet};
use crate::params::Params;

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
    /// The current model's left-out rows (cross-validation by setup), made once when first
    /// needed.
    pub base_cv: std::cell::OnceCell<Option<Vec<f64>>>,
}

/// One model of the search: the current model with `added`, its fit and how it predicts.
pub(crate) struct Entry<'a> {
    pub(in crate::diagnose) added: Vec<&'a dyn Effect>,
    /// A family of the current model with other parts, in place of the settled one (the
    /// parts a family keeps may change with the effect added).
    pub(in crate::diagnose) swap: Option<&'a dyn Effect>,
    pub(in crate::diagnose) fitted: Fitted,
    /// Held-out errors with each setup's zero removed (mm), where there are held-out data.
    pub(in crate::diagnose) held: Option<Vec<f64>>,
    /// Left-out rows (σ), where the held-out data do not decide against the current model.
    pub(in crate::diagnose) left_out: Option<Vec<f64>>,
    pub(in crate::diagnose) prediction: Option<Prediction>,
    pub(in crate::diagnose) p_value: f64,
    /// The Wald test of the added parameters alone ([`wald_p`]): part of `p_value`, and of the
    /// calibration's evidence in the judgement.
    pub(in crate::diagnose) wald_p: f64,
    /// The nested F-test's own p-value: part of `p_value`.
    pub(in crate::diagnose) f_p: f64,
    pub(in crate::diagnose) f_statistic: f64,
    pub(in crate::diagnose) k: f64,
    pub(in crate::diagnose) judged: Judged,
    pub(in crate::diagnose) relevant: bool,
    /// Index of the single candidate this entry is (None: a part subset or a pair).
    pub(in crate::diagnose) candidate: Option<usize>,
    /// The dictionary's test of its calibration residual, made once when first needed.
    structure: std::cell::OnceCell<sparse::Structure>,
    /// Left-out rows made for a comparison with another model where `left_out` is None
    /// (the held-out data decided against the current model, not between the two).
    left_out_later: std::cell::OnceCell<Option<Vec<f64>>>,
}

impl Entry<'_> {
    pub(in crate::diagnose) fn names(&self) -> Vec<String> {
        self.added.iter().map(|e| e.name().to_owned()).collect()
    }

    /// How simple it is: effects added, then parameters.
    pub(in crate::diagnose) fn complexity(&self) -> (usize, usize) {
        let params = self
            .fitted
            .fit
            .effect_params
            .iter()
            .filter(|p| p.physical() && self.added.iter().any(|e| e.name() == p.effect))
            .count();
        (self.added.len(), params)
    }

    /// The dictionary's test of its calibration residual.
    pub(in crate::diagnose) fn structure(&self, campaign: &Campaign) -> &sparse::Structure {
        self.structure
            .get_or_init(|| sparse::structure(campaign, &self.fitted.rows))
    }

    /// Whether a value it fitted lies outside what the physics allows: it absorbs something
    /// else, and no rule of the choice counts it against another model.
    pub(in crate::diagnose) fn unphysical(&self) -> bool {
        !self.judged.implausible.is_empty()
    }

    /// Whether it could be named.
    pub(in crate::diagnose) fn eligible(&self) -> bool {
        matches!(self.judged.outcome, Outcome::Outpredicted)
    }
}

pub(in crate::diagnose) fn clone_fitted(f: &Fitted) -> Fitted {
    Fitted {
        rows: f.rows.clone(),
        fit: f.fit.clone(),
    }
}

/// The parameters of the effects `added` among a fit's.
pub(in crate::diagnose) fn added_params(
    all: &[EffectEstimate],
    added: &[&dyn Effect],
) -> Vec<EffectEstimate> {
    all.iter()
        .filter(|p| added.iter().any(|e| e.name() == p.effect))
        .cloned()
        .collect()
}

impl<'j> Judge<'j> {
    /// The model with `added` (and `swap` for a family's part combination) fitted from
    /// `warm`, as an entry beside the single candidates; None where it cannot be fitted.
    pub(in crate::diagnose) fn tried<'a>(
        &self,
        (added, swap): (Vec<&'a dyn Effect>, Option<&'a dyn Effect>),
        warm: &[&Fitted],
    ) -> Option<Entry<'a>> {
        let fitted = self.fit((&added, swap), warm).ok()?;
        Some(self.entry((added, swap), fitted, None))
    }

    /// A model's entry: its nested test against the current model and its prediction.
    pub(in crate::diagnose) fn entry<'a>(
        &self,
        (added, swap): (Vec<&'a dyn Effect>, Option<&'a dyn Effect>),
        fitted: Fitted,
        candidate: Option<usize>,
    ) -> Entry<'a> {
        let base = &self.base.fit;
        let k = (base.dof - fitted.fit.dof).max(0.0);
        let nested = Nested::of((fitted.fit.chi2, fitted.fit.dof), (base.chi2, base.dof));
        let f_statistic = nested.map_or(0.0, |n| n.f);
        let names: Vec<&str> = added.iter().map(|e| e.name()).collect();
        let wald_p = wald_p(&fitted.fit, &names);
        let f_p = nested.map_or(1.0, |n| n.p);
        // the likelihood ratio, and the added parameters themselves (the Wald test)
        let p_value = if nested.is_some() {
            f_p.max(wald_p)
        } else {
            1.0
        };
        let relevant = relevant(
            fitted
                .fit
                .effect_params
                .iter()
                .filter(|p| added.iter().any(|e| e.name() == p.effect)),
        );
        let mut entry = Entry {
            added,
            swap,
            fitted,
            held: None,
            left_out: None,
            prediction: None,
            p_value,
            wald_p,
            f_p,
            f_statistic,
            k,
            judged: Judged::default(),
            relevant,
            candidate,
            structure: std::cell::OnceCell::new(),
            left_out_later: std::cell::OnceCell::new(),
        };
        self.predict(&mut entry);
        entry
    }

    /// The entry's prediction against the current model's: held-out data where they decide
    /// (better, clearly worse, or a change they resolve and do not follow), else the setups
    /// cross-validation leaves out, for a model that may matter.
    pub(in crate::diagnose) fn predict(&self, e: &mut Entry) {
        let held = self
            .val
            .and_then(|_| Prediction::scaled(&self.base.fit, &e.fitted.fit));
        if held.is_some() {
            e.held = e.fitted.fit.held_out.as_ref().map(|h| h.scaled.clone());
        }
        e.prediction = held;
        if held.is_some_and(|p| p.last_word()) {
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
            // a left-out setup's own parameters are the whole fit's, its rows among them
            let refit = e
                .fitted
                .fit
                .setup_params
                .saturating_sub(self.base.fit.setup_params);
            e.prediction = Prediction::compared(b, &rows).map(|p| Prediction {
                by_setup: true,
                ..p.refit(refit, rows.len())
            });
            e.left_out = Some(rows);
        }
    }

    /// The left-out rows of the model with `added` (cross-validation by setup).
    pub(in crate::diagnose) fn left_out(
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
    pub(in crate::diagnose) fn model_of<'e>(
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
    pub(in crate::diagnose) fn fit(
        &self,
        (added, swap): (&[&dyn Effect], Option<&dyn Effect>),
        warm: &[&Fitted],
    ) -> Result<Fitted, FitError> {
        let with = self.model_of(added, swap);
        let start = Params::nominal();
        let set = EffectSet::bind(&with, self.campaign, &start)?;
        let fits: Vec<&crate::diagnose::types::Fit> = std::iter::once(&self.base.fit)
            .chain(warm.iter().map(|w| &w.fit))
            .collect();
        let theta = warm_theta_among(&set, &fits);
        let (cal, _) = calib::calibrate(&Request {
            effects: &set,
            warm: Some(calib::WarmStart {
                params: &self.base.fit.params,
                theta: &theta,
                screen: false,
            }),
            leverages: false,
            ..Request::new(self.campaign, &start, self.copts)
        })?;
        finish_with(self.val, &with, &set, cal)
    }

    /// Whether model `big` beats model `small` (which it holds) by the evidence a candidate
    /// needs: the nested F-test between the two with their prediction (held-out where it
    /// decides, else left-out rows) combined below the level, not contradicted, better, by a
    /// gain that matters; the parameters `big` adds must themselves differ from zero (their
    /// Wald test) and reach a relevant size ([`relevant_beyond`]), as a candidate's must, and
    /// their gain must not be one that a single term
    /// of the dictionary matches while `big` still leaves structure ([`Judge::outdone_by_term`]).
    pub(in crate::diagnose) fn beats(&self, big: &Entry, small: &Entry) -> bool {
        let (b, s) = (&big.fitted.fit, &small.fitted.fit);
        let wald = wald_beyond(b, s);
        let gain = |prediction: Option<Prediction>| {
            Gain::of(
                (b.chi2, b.dof),
                (s.chi2, s.dof),
                self.base.rows.len(),
                prediction,
            )
            .with_wald(wald)
        };
        let held = held_between(small, big);
        let prediction = match held {
            Some(p) if p.last_word() => held,
            // the held-out data cannot tell the two apart (a noisy instrument, or an error
            // neither explains): the setups left out decide, where the calibration alone
            // would name the larger model
            _ if gain(None).needed(self.level) => self
                .left_out_of(small)
                .zip(self.left_out_of(big))
                .and_then(|(x, y)| {
                    Prediction::compared(x, y).map(|p| Prediction {
                        by_setup: true,
                        ..p.refit(b.setup_params.saturating_sub(s.setup_params), y.len())
                    })
                })
                .or(held),
            _ => held,
        };
        gain(prediction).needed(self.level)
            && relevant_beyond(b, s)
            && !self.outdone_by_term(big, small)
    }

    /// An entry's left-out rows, made when first needed.
    fn left_out_of<'e>(&self, e: &'e Entry) -> Option<&'e [f64]> {
        e.left_out.as_deref().or_else(|| {
            e.left_out_later
                .get_or_init(|| self.left_out((&e.added, e.swap), &e.fitted))
                .as_deref()
        })
    }

    /// Whether what `big` adds to `small` is part of something the library lacks: its gain
    /// (BIC) is no more than the best single dictionary term takes from `small`'s residual,
    /// and `big` leaves structure behind. The rule a model meets against the current one
    /// (a soft rod's force-following residual is partly a scale difference of the guides; a
    /// term of the forces explains more of it, and the structure stays).
    pub(in crate::diagnose) fn outdone_by_term(&self, big: &Entry, small: &Entry) -> bool {
        self.term_rivals(
            &big.fitted.fit,
            &small.fitted.fit,
            small.structure(self.campaign),
        ) && big.structure(self.campaign).p_value < self.structure_level
    }

    /// Whether the gain (BIC) of the fit `big` over `small` is no more than the best single
    /// dictionary term takes from `small`'s residual (`term`: its structure), in the same
    /// currency: a term's one parameter against the added ones.
    pub(in crate::diagnose) fn term_rivals(
        &self,
        big: &crate::diagnose::types::Fit,
        small: &crate::diagnose::types::Fit,
        term: &sparse::Structure,
    ) -> bool {
        let n = self.base.rows.len().max(1) as f64;
        let k = (small.dof - big.dof).max(0.0);
        small.chi2 - big.chi2 - k * n.ln() <= term.explained_chi2 - n.ln()
    }
}

/// The errors models are ranked by: held-out where there are held-out data, else left-out
/// rows.
pub(in crate::diagnose) fn ranked<'e>(e: &'e Entry) -> Option<&'e [f64]> {
    e.held.as_deref().or(e.left_out.as_deref())
}

pub(in crate::diagnose) fn rms_of(e: &Entry) -> f64 {
    ranked(e).map_or(f64::INFINITY, calib::rms)
}

/// Model `b` against model `a` on the held-out data.
fn held_between(a: &Entry, b: &Entry) -> Option<Prediction> {
    a.held
        .as_ref()
        .and(b.held.as_ref())
        .and_then(|_| Prediction::scaled(&a.fitted.fit, &b.fitted.fit))
}

/// The family variant an entry swaps into the current model, by name.
pub(in crate::diagnose) fn swapped<'e>(e: &'e Entry) -> Option<&'e str> {
    e.swap.map(Effect::name)
}

/// The parts of an effect in a model: those it pins (`thermal:rods`), every part of a family
/// named whole, none for an effect of one piece.
pub(in crate::diagnose) fn parts_of(e: &dyn Effect) -> Vec<String> {
    match e.name().split_once(':') {
        Some((_, parts)) => parts.split('+').map(str::to_owned).collect(),
        None => e.parts().iter().map(|p| (*p).to_owned()).collect(),
    }
}

/// Whether model `big` holds everything of `small` and more: every effect of `small` (or its
/// family with at least its parts), with the same family swapped in.
pub(in crate::diagnose) fn covers(big: &Entry, small: &Entry) -> bool {
    if swapped(big) != swapped(small) {
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
