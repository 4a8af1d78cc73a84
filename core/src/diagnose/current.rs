//! The current model as every command evaluates it: its instruments' noise estimated from the
//! campaign under the model itself (the same whatever candidates a diagnosis is offered),
//! its families named whole settled to the parts the data can tell apart, calibrated, and
//! judged on the held-out data. `rpkm diagnose` reports it as its baseline, `rpkm
//! calibrate` and the calibrator node as their held-out figures ([`evaluate`]).

use super::figures::length_sigmas;
use super::held_out::validation::{self, Validation};
use super::held_out::{self, Levels, Model1};
use super::search::settle::{self, Settled};
use super::search::trials::finish_held;
use super::types::{Baseline, DiagnoseError, DiagnosisOptions, Fit, Fitted, HeldOutCheck};
use crate::calib::{self, Calibration, Request};
use crate::campaign::Campaign;
use crate::effects::{Effect, EffectSet};
use crate::noise::{Group, NoiseModel, N_GROUPS};
use crate::obs::RowValue;
use crate::params::{Model, Params};
use crate::stats;
use crate::variance::NoiseEstimate;

/// Calibration options of the diagnosis: the model's links, every parameter under its
/// tolerance prior, no outlier elimination (the nested tests need the same rows in every
/// fit). `rpkm calibrate` and the calibrator node calibrate with the same selection.
pub fn calib_options(opts: &DiagnosisOptions) -> calib::Options {
    calib::Options {
        model: Model::M29,
        selection: calib::Selection::Prior(opts.prior),
        links: match opts.model {
            Model::M24 => calib::Link::perfect_parallelogram(),
            Model::M29 => Vec::new(),
        },
        outlier_sigma: None,
        noise: opts.noise.clone(),
        stop: opts.stop.clone(),
        ..Default::default()
    }
}

/// The model (`effects`) calibrated with `copts` as they are.
pub(crate) fn fit_model(
    campaign: &Campaign,
    effects: &[&dyn Effect],
    copts: &calib::Options,
) -> Result<Calibration, DiagnoseError> {
    let start = Params::nominal();
    let set = EffectSet::bind(effects, campaign, &start)?;
    calib::calibrate(&Request {
        effects: &set,
        ..Request::new(campaign, &start, copts)
    })
    .map(|(cal, _)| cal)
    .map_err(DiagnoseError::Baseline)
}

/// The model (`effects`) calibrated with the noise estimated from the campaign, the
/// estimate, and the calibration options with its weights. `first`: the estimation's first
/// round where it is at hand (the model calibrated at the stated noise).
pub(crate) fn noise_of(
    campaign: &Campaign,
    effects: &[&dyn Effect],
    opts: &DiagnosisOptions,
    first: Option<&Calibration>,
) -> Result<(Calibration, NoiseEstimate, calib::Options), DiagnoseError> {
    let start = Params::nominal();
    let set = EffectSet::bind(effects, campaign, &start)?;
    let mut copts = calib_options(opts);
    let (cal, est) = calib::calibrate(&Request {
        effects: &set,
        noise: opts.weighting,
        first_round: first,
        ..Request::new(campaign, &start, &copts)
    })
    .map_err(DiagnoseError::Baseline)?;
    copts.noise = est.model.clone();
    copts.noise_inflation = est.inflation;
    Ok((cal, est, copts))
}

/// The current model evaluated: what it is, its fit, the noise it shows, its held-out
/// figures and their judge.
pub(crate) struct Current {
    pub settled: Settled,
    /// The calibration, its rows in `fitted` (held once).
    pub cal: Calibration,
    pub fitted: Fitted,
    pub est: NoiseEstimate,
    pub copts: calib::Options,
    pub baseline: Baseline,
    pub held_out: Option<HeldOutCheck>,
}

/// Level of each structure test ([`Levels::at`]).
pub(crate) fn structure_level(opts: &DiagnosisOptions) -> f64 {
    Levels::at(opts.alpha).structure
}

impl Current {
    /// The model `in_model` as every command evaluates it (see the module documentation).
    /// `first`: the model calibrated at the stated noise, where the caller has it.
    pub fn of(
        campaign: &Campaign,
        validation: Option<&Campaign>,
        in_model: &[&dyn Effect],
        opts: &DiagnosisOptions,
        first: Option<&Calibration>,
    ) -> Result<Current, DiagnoseError> {
        let (cal, est, copts) = noise_of(campaign, in_model, opts, first)?;
        let val = validation::held_out(validation, &est.model)?;
        // the evidence a part needs: a candidate's level, over the part combinations
        let level = opts.alpha / settle::PART_COMBINATIONS;
        let settled = settle::settle(campaign, val.as_ref(), in_model, (&copts, level));
        let effects = settled.effects(in_model);
        // the noise is the settled model's: under the model named, a rod of another stiffness
        // left its misfit in the noise (a twin's rod 3 at 1.3x: the encoders read 4.92 µm
        // under the plain preload, 0.31 µm under the settled model)
        let (cal, est, copts, val) = if settled.changed() {
            let (cal, est, copts) = noise_of(campaign, &effects, opts, None)?;
            let val = validation::held_out(validation, &est.model)?;
            (cal, est, copts, val)
        } else {
            (cal, est, copts, val)
        };
        let set = EffectSet::bind(&effects, campaign, &cal.start)?;
        let model = (effects.as_slice(), &set);
        let (cal, fitted, held_out) = judged(val.as_ref(), model, cal, &est, opts)?;
        let baseline = baseline(&fitted, &est.model, opts);
        drop(effects);
        Ok(Current {
            settled,
            cal,
            fitted,
            est,
            copts,
            baseline,
            held_out,
        })
    }
}

impl Current {
    /// The current model of noise-free (simulated) data: the stated weights (there is no
    /// noise to estimate), the families whole.
    pub fn exact(
        (campaign, val): (&Campaign, Option<&Validation>),
        in_model: &[&dyn Effect],
        cal: Calibration,
        copts: &calib::Options,
        opts: &DiagnosisOptions,
    ) -> Result<Current, DiagnoseError> {
        let est = NoiseEstimate::assumed(&opts.noise);
        let set = EffectSet::bind(in_model, campaign, &cal.start)?;
        let (cal, fitted, held_out) = judged(val, (in_model, &set), cal, &est, opts)?;
        let baseline = baseline(&fitted, &est.model, opts);
        Ok(Current {
            settled: Settled::unchanged(in_model),
            cal,
            fitted,
            est,
            copts: copts.clone(),
            baseline,
            held_out,
        })
    }
}

/// The current model's statistics and its calibration, the calibration's rows moved into
/// the statistics (held once: 2·10⁵ rows are 26 MB, kept through the whole diagnosis), and
/// the held-out judge of it: the model's held-out θ fitted once, its figures made once and
/// read by both. `(effects, set)`: the model and its effects bound to the campaign; `est`:
/// the noise its floor is made of.
fn judged(
    val: Option<&Validation>,
    (effects, set): (&[&dyn Effect], &EffectSet),
    mut cal: Calibration,
    est: &NoiseEstimate,
    opts: &DiagnosisOptions,
) -> Result<(Calibration, Fitted, Option<HeldOutCheck>), DiagnoseError> {
    let rows = std::mem::take(&mut cal.residuals);
    let model = Model1 {
        effects,
        cal_set: set,
        cal: &cal,
    };
    let (held, check) = match val {
        Some(v) => {
            let refit = model.held_out_theta(v)?;
            let held = model.held_out(v, &refit)?;
            let levels = Levels::at(opts.alpha);
            let check = held_out::judge(v, (&model, &refit), held.clone(), &est.groups, &levels)?;
            (Some(held), Some(check))
        }
        None => (None, None),
    };
    let fitted = finish_held(
        held,
        set,
        Calibration {
            residuals: rows,
            ..cal.clone()
        },
    );
    Ok((cal, fitted, check))
}

/// The baseline's figures: its fit, the noise floor, and χ² against the stated noise.
pub(crate) fn baseline(base: &Fitted, estimated: &NoiseModel, opts: &DiagnosisOptions) -> Baseline {
    let held = base.fit.held_out.as_ref();
    let noise_floor = match held {
        Some(h) => h.noise_floor,
        None => calib::rms(&length_sigmas(&base.rows)),
    };
    // the same rows weighted by the rating
    let scale = chi2_reweighted(&base.rows, estimated, &opts.noise);
    let p_value = stats::chi2_upper_tail(scale, base.fit.dof);
    Baseline {
        cal_rms: base.fit.cal_rms,
        val_rms: held.map(|h| h.errors.rms),
        noise_floor,
        val_rms_relative: held.map(|h| h.errors.rms_relative),
        noise_floor_relative: held.map(|h| h.noise_floor_relative),
        chi2: scale,
        dof: base.fit.dof,
        chi2_per_dof: scale / base.fit.dof,
        p_value,
        consistent_with_noise: p_value > opts.alpha,
        held_out: base.fit.held_out.clone(),
    }
}

/// χ² of a fit's rows weighted by another noise than the one they were fitted under (`from`):
/// each group's part of a row's variance rescaled to that group's level in `to`. Under one
/// noise the χ² of several models compare; each under its own estimate reads about 1.
fn chi2_reweighted(rows: &[RowValue], from: &NoiseModel, to: &NoiseModel) -> f64 {
    let ratio2: [f64; N_GROUPS] = std::array::from_fn(|k| {
        let g = Group::ALL[k];
        (to.sigma(g, 1000.0) / from.sigma(g, 1000.0)).powi(2)
    });
    rows.iter()
        .map(|r| {
            let var: f64 = r.parts.iter().zip(&ratio2).map(|(v, f)| v * f).sum();
            r.value * r.value / var
        })
        .sum()
}

/// One model as `rpkm calibrate`, the calibrator node and the Calibrate action evaluate it:
/// the same calibration, noise and held-out judge as the diagnosis's baseline.
#[derive(Clone, Debug)]
pub struct Evaluated {
    /// The effects as fitted (a family named whole settled to its parts: `thermal:rods`).
    pub model_effects: Vec<String>,
    pub fit: Fit,
    pub noise: NoiseEstimate,
    pub calibration: Calibration,
    pub baseline: Baseline,
    pub held_out: Option<HeldOutCheck>,
    /// The calibration's rows as fitted, weighted by `noise`.
    pub rows: Vec<RowValue>,
}

impl Evaluated {
    /// χ²/ν of this model's calibration with its rows weighted by `noise` (another model's
    /// estimate, or the stated noise) instead of its own estimate: the figure that compares
    /// models, where each under its own estimate reads about 1.
    pub fn chi2_per_dof_under(&self, noise: &NoiseModel) -> f64 {
        chi2_reweighted(&self.rows, &self.noise.model, noise) / self.fit.dof
    }
}

/// Calibrate `campaign` with `effects` in the model as the diagnosis does (noise estimated,
/// tolerance prior, families settled) and judge it on the held-out data.
pub fn evaluate(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    effects: &[&dyn Effect],
    opts: &DiagnosisOptions,
) -> Result<Evaluated, DiagnoseError> {
    let current = Current::of(campaign, validation, effects, opts, None)?;
    let model_effects = current
        .settled
        .effects(effects)
        .iter()
        .map(|e| e.name().to_owned())
        .collect();
    let rows = std::sync::Arc::unwrap_or_clone(current.fitted.rows);
    Ok(Evaluated {
        model_effects,
        fit: current.fitted.fit,
        noise: current.est,
        // the calibration whole, its rows as fitted
        calibration: Calibration {
            residuals: rows.clone(),
            ..current.cal
        },
        baseline: current.baseline,
        held_out: current.held_out,
        rows,
    })
}
