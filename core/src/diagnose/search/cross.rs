//! Prediction without a validation campaign: cross-validation by setup. The campaign's
//! setups are dealt into folds; each fold is left out in turn, the model calibrated on the
//! others (warm from the whole campaign's fit), and the left-out setups' rows predicted by
//! that calibration. An effect that only absorbs the campaign's noise, or something else,
//! predicts the setups it has not seen worse than the model without it.
//!
//! A setup's own parameters (an instrument's alignment in that mounting) do not carry over
//! to another setup: a left-out setup's are the whole campaign's fit's, as a validation
//! campaign's are fitted on its own readings.

use crate::calib::{self, Request, WarmStart};
use crate::campaign::Campaign;
use crate::effects::{Effect, EffectSet, Slot};
use crate::obs::{Evaluation, Form, Pieces, Step};
use crate::params::Params;

/// Most folds: a campaign of many small setups is dealt into this many.
pub const MAX_FOLDS: usize = 10;

/// A model as fitted on the whole campaign: its effects, parameters and effect parameters.
pub struct Fitted<'a> {
    pub effects: &'a [&'a dyn Effect],
    pub params: &'a Params,
    pub theta: &'a [f64],
}

/// The rows of every setup (each in its noise, r/σ: every instrument and the drive forces),
/// each predicted by the model calibrated without its fold, in fold order and row order: the
/// same rows for any model of the same campaign.
/// None where the campaign has fewer than two setups or a fold cannot be calibrated.
pub fn predicted_rows(
    campaign: &Campaign,
    model: &Fitted,
    copts: &calib::Options,
) -> Option<Vec<f64>> {
    let setups = campaign.setups();
    if setups.len() < 2 {
        return None;
    }
    let n_folds = setups.len().min(MAX_FOLDS);
    let start = Params::nominal();
    let whole = EffectSet::bind(model.effects, campaign, &start).ok()?;
    let whole_layout = whole.layout();
    // each pose's fold, by its setup's place in the campaign (looked up once: a fold of a
    // thousand setups searched per pose and per row grew with the setups times the rows)
    let mut fold_of = vec![0; campaign.poses.len()];
    for (k, setup) in setups.iter().enumerate() {
        for &i in &setup.poses {
            fold_of[i] = k % n_folds;
        }
    }
    let mut out = Vec::new();
    for fold in 0..n_folds {
        let rest = Campaign {
            poses: campaign
                .poses
                .iter()
                .zip(&fold_of)
                .filter(|(_, &f)| f != fold)
                .map(|(p, _)| p.clone())
                .collect(),
            source: campaign.source.clone(),
            comments: campaign.comments.clone(),
            covariate_names: campaign.covariate_names.clone(),
        };
        let set = EffectSet::bind(model.effects, &rest, &start).ok()?;
        let layout = set.layout();
        let theta0 = by_name(&layout, &whole_layout, model.theta, None);
        let (cal, _) = calib::calibrate(&Request {
            effects: &set,
            warm: Some(WarmStart {
                params: model.params,
                theta: &theta0,
                screen: false,
            }),
            leverages: false,
            ..Request::new(&rest, &start, copts)
        })
        .ok()?;
        // the fold's machine; a setup's own parameters where the fold had that setup, else
        // the whole fit's
        let theta = by_name(&whole_layout, &layout, &cal.theta, Some(model.theta));
        // the fold's setups alone: the rows of the others were read and thrown away (ten
        // evaluations of the whole campaign on one thread, one per fold)
        let eval = Evaluation {
            campaign,
            p: &cal.params,
            model: copts.model,
            step: Step::Direct,
            p_cal: &start,
            corr: &whole.corrections(&theta, &cal.params),
            noise: &copts.noise,
            form: Form::Decorrelated,
        };
        let pieces = Pieces::of_setups(campaign, usize::MAX, |k| k % n_folds == fold);
        let mut rows = Vec::new();
        for k in 0..pieces.len() {
            eval.piece_into(&pieces, k, &mut rows).ok()?;
        }
        out.extend(
            rows.iter()
                .filter(|r| r.sigma > 0.0)
                .filter(|r| fold_of[r.pose] == fold)
                .map(|r| r.value / r.sigma),
        );
    }
    Some(out)
}

/// θ in the layout `to`, each slot from the slot of the same effect and name in `from`
/// (values `values`); a slot `from` lacks keeps `fallback`'s value at its own index, or 0.
fn by_name(to: &[Slot], from: &[Slot], values: &[f64], fallback: Option<&[f64]>) -> Vec<f64> {
    to.iter()
        .map(|slot| {
            from.iter()
                .find(|f| f.effect == slot.effect && f.param.name == slot.param.name)
                .and_then(|f| values.get(f.index).copied())
                .or_else(|| fallback.and_then(|v| v.get(slot.index).copied()))
                .unwrap_or(0.0)
        })
        .collect()
}
