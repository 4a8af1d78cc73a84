//! The rounds of a diagnosis.
//!
//! 1. At the stated noise: every candidate added to the current model and tested, to learn
//!    which stand out (under noise estimated with the current model, its misfit inflates the
//!    levels and dims the very effect that would explain it).
//! 2. The current model on its own ([`Current`]): its noise, its families settled, its
//!    held-out figures: the baseline, the same whatever candidates are offered.
//! 3. The candidates again, the rows weighted by the noise estimated under the current model
//!    with round 1's significant candidates (a model that misses an effect counts it as
//!    noise, and the next step of the loop, weighted otherwise, would judge another
//!    problem), and the model chosen as a whole ([`model::search`]).

use super::current::{calib_options, noise_of, structure_level, Current};
use super::figures::{error_vectors, length_values};
use super::held_out::validation;
use super::search::entry::{clone_fitted, Judge};
use super::search::model;
use super::search::pool::{self, Pool};
use super::search::trials::{candidates, finish, try_all, Round};
use super::structure::sparse;
use super::types::NUMERICAL_RMS_MM;
use super::types::{Candidate, DiagnoseError, DiagnosisOptions, Fit, Fitted, ModelDiagnosis};
use super::verdict::{conclude, Concluded};
use crate::calib::{self, Calibration};
use crate::campaign::Campaign;
use crate::effects::{self, Effect, Family};
use crate::params::Model;

/// Diagnose `campaign` with `in_model` effects already in the model; `validation` is held out.
pub fn diagnose(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    in_model: &[&dyn Effect],
    opts: &DiagnosisOptions,
) -> Result<ModelDiagnosis, DiagnoseError> {
    diagnose_among(campaign, validation, in_model, &[], opts)
}

/// [`diagnose`], with the effects `offered` (written ones, `effects::Written`) tried as
/// candidates beside the library's: the same tests, at the same level for each.
pub fn diagnose_among(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    in_model: &[&dyn Effect],
    offered: &[&dyn Effect],
    opts: &DiagnosisOptions,
) -> Result<ModelDiagnosis, DiagnoseError> {
    let diagnosis = rounds(campaign, validation, in_model, offered, opts);
    // a fit stopped part-way fails as it can (a candidate not fitted, a round's error):
    // whatever came of it, a stopped diagnosis concludes nothing
    if opts.stopped() {
        return Err(DiagnoseError::Cancelled);
    }
    diagnosis
}

/// The rounds of [`diagnose_among`] (see the module documentation).
fn rounds(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    in_model: &[&dyn Effect],
    offered: &[&dyn Effect],
    opts: &DiagnosisOptions,
) -> Result<ModelDiagnosis, DiagnoseError> {
    let library = effects::library();
    let found = candidates_of(&library, in_model, offered, opts);
    let pinned = pinned_beside(&found, in_model);
    let tried = with_pinned(&found, &pinned);
    let variants = pool::part_variants(&tried, false);
    let followers = pool::followers(&library, &tried);
    let swaps = pool::part_variants(in_model, true);
    let level = opts.alpha / tried.len().max(1) as f64;
    let stated = calib_options(opts);
    let first = Search {
        campaign,
        validation,
        in_model,
        tried: &tried,
        level,
        threads: opts.threads,
        screen: opts.screen,
    };
    let (base1, round1, cal1) = first.round(&stated, None, true)?;
    not_stopped(opts)?;
    // noise-free (simulated) data: no noise to estimate, the stated weights stay
    if calib::rms(&length_values(&base1.rows)) < NUMERICAL_RMS_MM {
        let pool = Pool {
            tried: &tried,
            variants: &variants,
            followers: &followers,
            swaps: &[],
        };
        return exact(&first, (base1, round1, cal1), (&pool, level), opts);
    }
    let current = Current::of(campaign, validation, in_model, opts, cal1.as_ref())?;
    not_stopped(opts)?;
    let settled = current.settled.effects(in_model);
    let (copts, compared_under, under_current) = comparison_weights(
        (campaign, opts),
        &current,
        &settled,
        (&round1.candidates, &tried),
    );
    drop(cal1);
    let pinned_second = pinned_beside(&tried, &settled);
    let tried_second = with_pinned(&tried, &pinned_second);
    let variants_second = pool::part_variants(&tried_second, false);
    let second = Search {
        in_model: &settled,
        tried: &tried_second,
        ..first
    };
    let (base, mut round) =
        second.again(&current, (&copts, under_current, &stated), (base1, round1))?;
    let val = validation::held_out(validation, &copts.noise)?;
    // the noise the comparisons are weighted with: the current model's own may hold what it
    // misses
    let judge = judge_of(&second, val.as_ref(), (&base, &copts), opts);
    let structure = sparse::structure(campaign, &base.rows);
    let (trials, choice) = model::search(
        &judge,
        (&mut round.candidates, &round.fits),
        &Pool {
            tried: &tried_second,
            variants: &variants_second,
            followers: &followers,
            swaps: &swaps,
        },
        &structure,
    );
    Ok(conclude(Concluded {
        campaign,
        opts,
        in_model,
        model_effects: &settled,
        base: &base,
        structure: &structure,
        current: &current,
        round,
        trials,
        choice,
        compared_under,
        level,
        tried: tried.len(),
    }))
}

/// Cancelled where the diagnosis was stopped: a round's result is not waited for.
fn not_stopped(opts: &DiagnosisOptions) -> Result<(), DiagnoseError> {
    if opts.stopped() {
        return Err(DiagnoseError::Cancelled);
    }
    Ok(())
}

/// For each candidate, the same effect pinned to the parts its family settled to in the
/// model, where it refines that family and is named whole ([`Effect::beside`]:
/// `thermal_lag` lags the parts `thermal` keeps, `thermal_lag:frame+scales`), else None. A
/// lag of a part the model does not expand is no physics: fitted there, it stands in for
/// the part's expansion left out (a campaign that cannot tell the rods from the frame).
fn pinned_beside(tried: &[&dyn Effect], settled: &[&dyn Effect]) -> Vec<Option<Box<dyn Effect>>> {
    tried
        .iter()
        .map(|e| {
            let parts = super::search::settle::parts_beside(settled, *e)?;
            (parts.len() < e.parts().len())
                .then(|| e.with_parts(&parts))
                .flatten()
        })
        .collect()
}

/// `tried` with each effect [`pinned_beside`] pinned in its place.
fn with_pinned<'a>(
    tried: &[&'a dyn Effect],
    pinned: &'a [Option<Box<dyn Effect>>],
) -> Vec<&'a dyn Effect> {
    tried
        .iter()
        .zip(pinned)
        .map(|(e, p)| p.as_deref().unwrap_or(*e))
        .collect()
}

/// Whether two calibrations' options weight the rows alike: the same noise and inflation
/// (every other option is [`calib_options`]' in both).
fn same_weights(a: &calib::Options, b: &calib::Options) -> bool {
    a.noise == b.noise && a.noise_inflation.to_bits() == b.noise_inflation.to_bits()
}

/// Whether two fits are the same to the bit: parameters, effect parameters and χ².
fn same_fit(a: &Fit, b: &Fit) -> bool {
    let same = |x: &[f64], y: &[f64]| {
        x.len() == y.len() && x.iter().zip(y).all(|(u, v)| u.to_bits() == v.to_bits())
    };
    same(&a.params.0, &b.params.0)
        && same(&a.theta, &b.theta)
        && a.chi2.to_bits() == b.chi2.to_bits()
        && a.dof.to_bits() == b.dof.to_bits()
}

/// The effects a diagnosis tries: the library's and the offered, less those whose family is
/// in the model in any form, those that refine a family not in it ([`Effect::beside`]:
/// `thermal_lag` without `thermal`), and the parallel-holder under model 29 (which has its
/// parameters already).
fn candidates_of<'a>(
    library: &'a [Box<dyn Effect>],
    in_model: &[&dyn Effect],
    offered: &[&'a dyn Effect],
    opts: &DiagnosisOptions,
) -> Vec<&'a dyn Effect> {
    let in_families: Vec<&str> = in_model
        .iter()
        .map(|e| effects::family_of(e.name()))
        .collect();
    library
        .iter()
        .map(std::convert::AsRef::as_ref)
        .chain(offered.iter().copied())
        .filter(|e| !in_families.contains(&effects::family_of(e.name())))
        .filter(|e| e.beside().is_none_or(|f| in_families.contains(&f)))
        .filter(|e| {
            !(Family::of(e.name()) == Some(Family::Parallelogram) && opts.model == Model::M29)
        })
        .collect()
}

/// The weights the candidates are compared with: the noise estimated under the current model
/// (settled) with round 1's significant candidates (fitted together, else the strongest
/// alone) and the names of those; the current model's own where none stood out or none of
/// them can be fitted (then `true`: the current model's calibration is the comparison's).
fn comparison_weights(
    (campaign, opts): (&Campaign, &DiagnosisOptions),
    current: &Current,
    settled: &[&dyn Effect],
    (round1, tried): (&[Candidate], &[&dyn Effect]),
) -> (calib::Options, Vec<String>, bool) {
    let under = noise_model(settled, round1, tried, Candidates::Significant);
    if under.len() == settled.len() {
        return (current.copts.clone(), Vec::new(), true);
    }
    let (under, copts) = if let Ok((_, _, copts)) = noise_of(campaign, &under, opts, None) {
        (under, copts)
    } else {
        // the significant candidates together cannot be fitted (one absorbs another to a
        // singular step): the strongest alone, else the current model's own (the comparison
        // is then the current model's, and no fit of a candidate is called the current
        // model's)
        let one = noise_model(settled, round1, tried, Candidates::Strongest);
        let Ok((_, _, copts)) = noise_of(campaign, &one, opts, None) else {
            return (current.copts.clone(), Vec::new(), true);
        };
        (one, copts)
    };
    let names = under[settled.len()..]
        .iter()
        .map(|e| e.name().to_owned())
        .collect();
    (copts, names, false)
}

/// The diagnosis of noise-free (simulated) data: the stated weights, no noise estimated.
fn exact(
    first: &Search,
    (base, mut round, cal): (Fitted, Round, Option<Calibration>),
    (pool, level): (&Pool, f64),
    opts: &DiagnosisOptions,
) -> Result<ModelDiagnosis, DiagnoseError> {
    let stated = calib_options(opts);
    let val = validation::held_out(first.validation, &opts.noise)?;
    let cal = base_cal(first, cal, &stated)?;
    let current = Current::exact(
        (first.campaign, val.as_ref()),
        first.in_model,
        cal,
        &stated,
        opts,
    )?;
    let judge = judge_of(first, val.as_ref(), (&base, &stated), opts);
    let structure = sparse::structure(first.campaign, &base.rows);
    let (trials, choice) = model::search(
        &judge,
        (&mut round.candidates, &round.fits),
        pool,
        &structure,
    );
    Ok(conclude(Concluded {
        campaign: first.campaign,
        opts,
        in_model: first.in_model,
        model_effects: first.in_model,
        base: &base,
        structure: &structure,
        current: &current,
        round,
        trials,
        choice,
        compared_under: Vec::new(),
        level,
        tried: first.tried.len(),
    }))
}

/// The judge of `search`'s candidates against its current model `base`, fitted with `copts`.
fn judge_of<'a>(
    search: &Search<'a>,
    val: Option<&'a validation::Validation<'a>>,
    (base, copts): (&'a Fitted, &'a calib::Options),
    opts: &DiagnosisOptions,
) -> Judge<'a> {
    Judge {
        campaign: search.campaign,
        val,
        in_model: search.in_model,
        base,
        copts,
        level: search.level,
        structure_level: structure_level(opts),
        base_cv: std::cell::OnceCell::new(),
    }
}

/// The current model's calibration of a round: the one the round made, else made here.
fn base_cal(
    search: &Search,
    cal: Option<Calibration>,
    copts: &calib::Options,
) -> Result<Calibration, DiagnoseError> {
    match cal {
        Some(cal) => Ok(cal),
        None => super::current::fit_model(search.campaign, search.in_model, copts),
    }
}

/// What every round of a diagnosis shares.
#[derive(Clone, Copy)]
pub(crate) struct Search<'a> {
    pub campaign: &'a Campaign,
    pub validation: Option<&'a Campaign>,
    pub in_model: &'a [&'a dyn Effect],
    pub tried: &'a [&'a dyn Effect],
    /// Level of each candidate's test (Bonferroni over the candidates).
    level: f64,
    /// Threads the candidates are fitted on.
    threads: usize,
    /// Whether candidates are screened first ([`DiagnosisOptions::screen`]).
    screen: bool,
}

impl Search<'_> {
    /// The current model and every candidate, calibrated with `copts` (its noise weights the
    /// rows and the held-out errors); the current model's calibration with `copts` and its
    /// statistics ([`finish`]'s) when they are at hand (`made`), else made here and the
    /// calibration returned where `keep` (a copy of its rows held through the candidates'
    /// fits only where a later step reads it).
    fn round(
        &self,
        copts: &calib::Options,
        made: Option<(&Calibration, Fitted)>,
        keep: bool,
    ) -> Result<(Fitted, Round, Option<Calibration>), DiagnoseError> {
        let val = validation::held_out(self.validation, &copts.noise)?;
        let (base, vectors, made) = if let Some((cal, base)) = made {
            (base, self.vectors(cal, copts), None)
        } else {
            let cal = super::current::fit_model(self.campaign, self.in_model, copts)?;
            let vectors = self.vectors(&cal, copts);
            let made = keep.then(|| cal.clone());
            let base = finish(self.campaign, val.as_ref(), self.in_model, cal)?;
            (base, vectors, made)
        };
        let tries = try_all(
            self.campaign,
            val.as_ref(),
            (self.in_model, &base.fit),
            self.tried,
            copts,
            (self.threads, self.screen),
        );
        let round = Round {
            vectors,
            ..candidates(self.campaign, self.tried, tries, &base, self.level)
        };
        Ok((base, round, made))
    }

    /// Round 2 (this search: the model as settled) under the comparisons' weights `copts`
    /// (`under_current`: the current model's own); round 1's fits (`first`) where nothing
    /// moved: nothing stood out, the noise is the stated one (`stated`'s weights to the bit),
    /// no family settled otherwise and the current model's calibration is round 1's. Round 2
    /// would make those fits again, to the bit (on 10⁵ poses of a machine with nothing
    /// missing, a third of the diagnosis).
    fn again(
        &self,
        current: &Current,
        (copts, under_current, stated): (&calib::Options, bool, &calib::Options),
        first: (Fitted, Round),
    ) -> Result<(Fitted, Round), DiagnoseError> {
        let (base1, round1) = first;
        if under_current
            && !current.settled.changed()
            && same_weights(copts, stated)
            && same_fit(&base1.fit, &current.fitted.fit)
        {
            return Ok((clone_fitted(&current.fitted), round1));
        }
        // round 1 has told which candidates stand out: its fits (every candidate's rows) are
        // not held through round 2's
        drop((base1, round1));
        // under the current model's own weights its calibration and statistics are at hand
        // (shared, not copied: 2·10⁵ rows are 26 MB)
        let made = under_current.then(|| (&current.cal, clone_fitted(&current.fitted)));
        let (base, round, _) = self.round(copts, made, false)?;
        Ok((base, round))
    }

    /// The current model's TCP error vectors under its calibration `cal`: a picture, not a
    /// number the verdict rests on (a pose the forward model cannot solve costs the arrows,
    /// not the diagnosis).
    fn vectors(
        &self,
        cal: &Calibration,
        copts: &calib::Options,
    ) -> Result<Vec<super::types::ErrorVector>, String> {
        error_vectors(self.campaign, self.in_model, cal, copts.model).map_err(|e| e.to_string())
    }
}

/// Which of round 1's candidates join the current model for the noise estimate.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Candidates {
    /// Every significant one that could be named.
    Significant,
    /// The most significant alone.
    Strongest,
}

/// The model the noise of the comparisons is estimated under: the current model and round
/// 1's candidates `which`, most significant first.
fn noise_model<'a>(
    in_model: &[&'a dyn Effect],
    candidates: &[Candidate],
    tried: &[&'a dyn Effect],
    which: Candidates,
) -> Vec<&'a dyn Effect> {
    let mut open: Vec<&Candidate> = candidates
        .iter()
        .filter(|c| c.significant && c.relevant)
        .collect();
    open.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
    if which == Candidates::Strongest {
        open.truncate(1);
    }
    let added = open
        .iter()
        .filter_map(|c| tried.iter().find(|e| e.name() == c.effect).copied());
    in_model.iter().copied().chain(added).collect()
}
