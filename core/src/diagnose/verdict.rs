//! The verdict. A model named by the search is the missing effect (and its partner). Without
//! one, nothing is missing only where all three hold: no structure in the calibration's
//! residual, a held-out RMS (each setup's zero removed) consistent with the model's floor, and
//! no structure in the held-out residual. Otherwise the residual's structure is unexplained:
//! the calibration campaign's, or, where the model explains the calibration campaign but not
//! the held-out data, the held-out data's, by how much and what they follow.

use super::current::{structure_level, Current};
use super::figures::{groups, length_values, noise_map, noisier, points};
use super::search::model::Choice;
use super::search::trials::Round;
use super::structure::carried;
use super::structure::sparse;
use super::structure::Shape;
use super::types::NUMERICAL_RMS_MM;
use super::types::{DiagnosisOptions, Fitted, ModelDiagnosis, ModelTrial, Test, VerdictKind};
use crate::calib;
use crate::campaign::Campaign;
use crate::effects::{self, Effect};

/// What a verdict is concluded from.
pub(crate) struct Concluded<'a> {
    pub campaign: &'a Campaign,
    pub opts: &'a DiagnosisOptions,
    /// The effects as given, and as fitted (families settled).
    pub in_model: &'a [&'a dyn Effect],
    pub model_effects: &'a [&'a dyn Effect],
    /// The current model's fit under the comparisons' weights, and the dictionary's test
    /// of its residual (made for the search: the same rows, the same test).
    pub base: &'a Fitted,
    pub structure: &'a sparse::Structure,
    /// The current model on its own: the baseline and the held-out judge.
    pub current: &'a Current,
    pub round: Round,
    pub trials: Vec<ModelTrial>,
    pub choice: Option<Choice>,
    pub compared_under: Vec<String>,
    /// Level of each candidate's test, and how many were tried.
    pub level: f64,
    pub tried: usize,
}

/// The diagnosis from the last round.
pub(crate) fn conclude(c: Concluded) -> ModelDiagnosis {
    let Concluded {
        campaign,
        opts,
        base,
        current,
        ..
    } = c;
    let level = structure_level(opts);
    let (carried, structure, shape) = tested(&c, level);
    let test = test_of(&c, level);
    let Round {
        mut candidates,
        skipped,
        vectors,
        ..
    } = c.round;
    candidates.sort_by(|a, b| b.bic_gain.total_cmp(&a.bic_gain));
    let exact = calib::rms(&length_values(&base.rows)) < NUMERICAL_RMS_MM;
    let held_out = current.held_out.clone();
    let (verdict_kind, unexplained) = kind_of(
        (campaign, &shape),
        held_out.as_ref(),
        c.choice.as_ref(),
        (exact, level),
    );
    let missing_effects: Vec<String> = c
        .choice
        .as_ref()
        .map(|ch| ch.added.clone())
        .unwrap_or_default();
    let fit = &current.fitted.fit;
    ModelDiagnosis {
        model: opts.model,
        effects_in_model: c.in_model.iter().map(|e| e.name().to_owned()).collect(),
        model_effects: c
            .model_effects
            .iter()
            .map(|e| e.name().to_owned())
            .collect(),
        effect_values: fit.effect_params.clone(),
        verdict_kind,
        missing_effect: missing_effects.first().map(|n| to_add(n)),
        together_with: missing_effects.get(1).map(|n| to_add(n)),
        missing_effects,
        chi2_per_dof: fit.chi2_per_dof,
        parameters: crate::params::NAMES
            .iter()
            .enumerate()
            .map(|(i, n)| ((*n).to_owned(), fit.params[i]))
            .collect(),
        noise: noise_map(&current.est.groups),
        compared_under: c.compared_under,
        noise_groups: current.est.groups.clone(),
        determined: fit.determined,
        baseline: current.baseline.clone(),
        held_out,
        candidates,
        trials: c.trials,
        skipped,
        structure,
        periodic: shape.periodic,
        carried,
        neighbours: shape.neighbours,
        resettled: c.choice.as_ref().and_then(|ch| ch.resettled.clone()),
        undecided: current.settled.undecided.clone(),
        tied_term: c.choice.and_then(|ch| ch.tied_term),
        noisier_than_rated: noisier(&current.est.groups),
        unexplained,
        groups: groups(&current.fitted.rows),
        points: points(campaign, &current.fitted.rows),
        error_vectors_missing: vectors.as_ref().err().cloned(),
        error_vectors: vectors.unwrap_or_default(),
        test,
    }
}

/// What the diagnosis tested with, and at which levels (`level`: the structure tests').
fn test_of(c: &Concluded, level: f64) -> Test {
    Test {
        noise_rounds: c.current.est.rounds,
        candidate_level: c.level,
        candidates_tried: c.tried,
        dictionary_level: level,
        held_out_level: c.opts.alpha,
        rows: c.base.rows.len(),
    }
}

/// The structure tests of the current model's residual (`c.base`'s rows), at `level`: where
/// the model reads a thermometer's history, without the part its readings' noise makes
/// through it (a lag's smooth error is no missing effect), and what that took.
fn tested(c: &Concluded, level: f64) -> (Option<carried::Carried>, sparse::Structure, Shape) {
    let fitted = carried::Fitted {
        effects: c.model_effects,
        params: &c.base.fit.params,
        theta: &c.base.fit.theta,
        model: c.opts.model,
        noise: &c.current.copts.noise,
    };
    if let Some((rows, carried)) = carried::without_carried(c.campaign, &fitted, &c.base.rows) {
        let structure = sparse::structure(c.campaign, &rows);
        let shape = Shape::with(c.campaign, &rows, level, structure.clone());
        return (Some(carried), structure, shape);
    }
    let structure = c.structure.clone();
    let shape = Shape::with(c.campaign, &c.base.rows, level, structure.clone());
    (None, structure, shape)
}

/// The name `--effects` takes to add an effect: a family by its name, its parts left to the
/// data (`thermal` for `thermal:rods`: the next diagnosis settles the same parts).
fn to_add(name: &str) -> String {
    effects::family_of(name).to_owned()
}

/// The verdict's kind, and what the residual left by its model follows while structured
/// (the held-out residual's term where only the held-out data are structured).
fn kind_of(
    (campaign, shape): (&Campaign, &Shape),
    held_out: Option<&super::types::HeldOutCheck>,
    choice: Option<&Choice>,
    (exact, level): (bool, f64),
) -> (VerdictKind, Option<sparse::Pointer>) {
    let disagrees = held_out.is_some_and(|h| !h.agrees()) && !exact;
    let structured = shape.structured() && !exact;
    let kind = match (choice, structured) {
        (Some(_), _) => VerdictKind::MissingEffect,
        (None, true) => VerdictKind::UnexplainedStructure,
        (None, false) if disagrees => VerdictKind::UnexplainedStructure,
        (None, false) => VerdictKind::NothingMissing,
    };
    if exact {
        return (kind, None);
    }
    if kind == VerdictKind::UnexplainedStructure && !structured {
        return (kind, held_out.and_then(|h| h.follows.clone()));
    }
    // without a model named, the residual left is the current model's, tested already
    let left = match choice {
        Some(ch) => &sparse::structure(campaign, &ch.fitted.rows),
        None => &shape.dictionary,
    };
    (
        kind,
        (left.p_value < level)
            .then(|| left.pointer.clone())
            .flatten(),
    )
}
