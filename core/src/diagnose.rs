//! Model discovery: where the model fails, which physical effect is missing, and what the
//! held-out error becomes once it is added.
//!
//! 1. Calibrate the current model (geometry + the effects already in it) and test its
//!    residual against the instruments' noise: χ² = Σ (r/σ)² against χ²(ν), ν = rows −
//!    identified parameters. The σ are the instruments' own (`noise`), so a χ²/dof near 1
//!    means the model explains the data to the noise.
//! 2. For each effect of the library not in the model: bind it (it may not apply: no
//!    temperature column, no drive forces), calibrate with it, and compare with the nested
//!    F-test F = (Δχ²/k) / (χ²₁/ν₁) (k: its identified parameters), at level α/m (Bonferroni
//!    over the m candidates). Rank by the Bayesian information criterion's improvement
//!    Δχ² − k ln n, best first; report the fraction of the residual above the noise it
//!    explains, and the held-out RMS before and after.
//! 3. The verdict: the best candidate when the residual is not noise, it is significant and
//!    explains at least [`Options::min_explained`] of the excess; none when the residual is
//!    consistent with noise.
//! 4. A structured residual that no effect explains is pointed at by correlation with the
//!    campaign's covariates, drive forces, time and workspace polynomials ([`sparse`]).

pub mod sparse;
pub mod stats;

use crate::calib::{self, Calibration, CalibrationError, EffectEstimate};
use crate::campaign::{Campaign, Instrument};
use crate::effects::{self, Effect, EffectSet, NotApplicable};
use crate::geometry;
use crate::noise;
use crate::obs::{self, PoseError, Residual, Step};
use crate::params::{Model, Params};
use nalgebra::{DMatrix, DVector, Vector2};

/// Options of a diagnosis.
#[derive(Clone, Debug)]
pub struct Options {
    /// The geometric model (24: rod 5 linked to rod 4).
    pub model: Model,
    /// Significance level of the tests (family-wise over the candidates).
    pub alpha: f64,
    /// Fraction of the residual above the noise a candidate must explain to be named.
    pub min_explained: f64,
    /// Condition-number limit of the geometric parameter selection.
    pub max_condition: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            model: Model::M24,
            alpha: 0.001,
            min_explained: 0.35,
            max_condition: 1e5,
        }
    }
}

/// A diagnosis that could not be made.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("calibrating the current model: {0}")]
    Baseline(#[source] CalibrationError),
    #[error("effect in the model: {0}")]
    Effect(#[from] NotApplicable),
    #[error("held-out data: {0}")]
    Validation(#[source] PoseError),
}

/// The fit of one model (the current one, or with a candidate effect).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Fit {
    /// χ² = Σ (r/σ)² of the calibration rows, its degrees of freedom and χ²/ν.
    pub chi2: f64,
    pub dof: usize,
    pub chi2_per_dof: f64,
    /// RMS of the length rows of the calibration (µm).
    pub cal_rms_um: f64,
    /// RMS of the held-out TCP errors (µm), if there are held-out data.
    pub val_rms_um: Option<f64>,
    /// Effect parameters identified.
    pub effect_params: Vec<EffectEstimate>,
    /// The identified geometric parameters.
    #[serde(skip)]
    pub params: Params,
}

/// The current model's fit and its test against noise (the JSON's `baseline`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Baseline {
    pub cal_rms_um: f64,
    pub val_rms_um: Option<f64>,
    /// RMS that noise alone would give on the held-out errors (or, without held-out data, on
    /// the calibration's length rows), µm.
    pub noise_floor_um: f64,
    pub chi2: f64,
    pub dof: usize,
    pub chi2_per_dof: f64,
    /// P(χ²_ν ≥ χ²): small when the residual is more than noise.
    pub p_value: f64,
    pub consistent_with_noise: bool,
}

/// An effect tried as an addition to the model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Candidate {
    pub effect: String,
    pub significant: bool,
    /// Fraction of the calibration's χ² above the noise (χ² − ν) the effect removes, 0..1.
    pub explained_fraction: f64,
    pub val_rms_before_um: Option<f64>,
    pub val_rms_after_um: Option<f64>,
    pub chi2_per_dof_after: f64,
    /// Nested F-test: statistic, its degrees of freedom and p-value.
    pub f_statistic: f64,
    pub f_dof: (usize, usize),
    pub p_value: f64,
    /// Improvement of the Bayesian information criterion (Δχ² − k ln n): the ranking.
    pub bic_gain: f64,
    /// The effect's parameters as identified.
    pub params: Vec<EffectEstimate>,
    /// A sentence an engineer can check.
    pub evidence: String,
}

/// An effect that could not be tried, and why.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Skipped {
    pub effect: String,
    pub reason: String,
}

/// RMS of one instrument direction against its noise.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GroupRms {
    pub instrument: String,
    pub direction: String,
    pub rows: usize,
    /// µm (µrad for ψ).
    pub rms: f64,
    pub noise: f64,
    pub chi2_per_row: f64,
}

/// One calibration residual, located for plots (heat maps over the workspace, against time
/// and covariates).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Point {
    pub pose: usize,
    pub line: usize,
    pub instrument: String,
    pub direction: String,
    /// TCP of the pose (nominal forward model of q1, q4), mm.
    pub x: f64,
    pub y: f64,
    pub t: f64,
    /// Residual and its σ: µm (µrad for ψ).
    pub value: f64,
    pub sigma: f64,
}

/// The diagnosis (serialises to the JSON other tools read: `missing_effect`, `baseline`,
/// `candidates`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Diagnosis {
    pub model: String,
    pub effects_in_model: Vec<String>,
    pub missing_effect: Option<String>,
    pub verdict: String,
    pub baseline: Baseline,
    pub candidates: Vec<Candidate>,
    pub skipped: Vec<Skipped>,
    /// What the residual left by the verdict's model follows, when it is still not noise.
    pub unexplained: Option<sparse::Pointer>,
    pub groups: Vec<GroupRms>,
    /// Residuals of the current model, worst (largest |r/σ|) first.
    pub points: Vec<Point>,
    pub test: String,
}

/// What one fit produced: its final rows and statistics.
struct Fitted {
    rows: Vec<Residual>,
    fit: Fit,
}

/// Held-out data with their noise.
struct Validation<'a> {
    campaign: &'a Campaign,
    /// σ of each held-out TCP error, in [`obs::tcp_errors`] order.
    sigma: Vec<f64>,
}

/// Diagnose `campaign` with `in_model` effects already in the model; `validation` is held out.
pub fn diagnose(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    in_model: &[&dyn Effect],
    opts: &Options,
) -> Result<Diagnosis, DiagnoseError> {
    let start = Params::nominal();
    let val = held_out(validation)?;
    let base = fit(campaign, val.as_ref(), in_model, &start, opts)?;
    let n_rows = base.rows.len();
    let p_value = stats::chi2_upper_tail(base.fit.chi2, base.fit.dof as f64);
    let consistent = p_value > opts.alpha;
    let noise_floor_um = match &val {
        Some(v) => calib::rms(&v.sigma) * 1e3,
        None => calib::rms(&length_sigmas(&base.rows)) * 1e3,
    };
    let baseline = Baseline {
        cal_rms_um: base.fit.cal_rms_um,
        val_rms_um: base.fit.val_rms_um,
        noise_floor_um,
        chi2: base.fit.chi2,
        dof: base.fit.dof,
        chi2_per_dof: base.fit.chi2_per_dof,
        p_value,
        consistent_with_noise: consistent,
    };

    let in_names: Vec<&str> = in_model.iter().map(|e| e.name()).collect();
    let library = effects::library();
    let tried: Vec<&dyn Effect> = library
        .iter()
        .map(|e| e.as_ref())
        .filter(|e| !in_names.contains(&e.name()))
        .filter(|e| !(e.name() == "parallelogram" && opts.model == Model::M29))
        .collect();
    let level = opts.alpha / tried.len().max(1) as f64;
    let mut candidates = Vec::new();
    let mut skipped = Vec::new();
    let mut fits = Vec::new();
    for effect in &tried {
        let mut with: Vec<&dyn Effect> = in_model.to_vec();
        with.push(*effect);
        match fit(campaign, val.as_ref(), &with, &start, opts) {
            Ok(m) => {
                let c = compare(
                    &base,
                    &m,
                    effect.name(),
                    effect.covariates(),
                    campaign,
                    level,
                );
                match c {
                    Some(c) => {
                        candidates.push(c);
                        fits.push((effect.name(), m));
                    }
                    None => skipped.push(Skipped {
                        effect: effect.name().to_owned(),
                        reason: "no parameter of it is observable with this campaign (the \
                                 geometry absorbs its signature)"
                            .to_owned(),
                    }),
                }
            }
            Err(e) => skipped.push(Skipped {
                effect: effect.name().to_owned(),
                reason: e.to_string(),
            }),
        }
    }
    candidates.sort_by(|a, b| b.bic_gain.total_cmp(&a.bic_gain));
    let best = candidates
        .first()
        .filter(|c| !consistent && c.significant && c.explained_fraction >= opts.min_explained);
    let missing_effect = best.map(|c| c.effect.clone());
    // what remains after the verdict's model
    let remaining: &Fitted = missing_effect
        .as_ref()
        .and_then(|m| fits.iter().find(|f| f.0 == m))
        .map_or(&base, |f| &f.1);
    let remaining_p = stats::chi2_upper_tail(remaining.fit.chi2, remaining.fit.dof as f64);
    let unexplained = if remaining_p <= opts.alpha {
        sparse::point_at(campaign, &remaining.rows)
    } else {
        None
    };
    let verdict = verdict(
        &baseline,
        best,
        &candidates,
        unexplained.as_ref(),
        &in_names,
    );
    Ok(Diagnosis {
        model: format!("{}", opts.model),
        effects_in_model: in_names.iter().map(|s| (*s).to_owned()).collect(),
        missing_effect,
        verdict,
        baseline,
        candidates,
        skipped,
        unexplained,
        groups: groups(&base.rows),
        points: points(campaign, &base.rows),
        test: format!(
            "chi-square test of the residual against the instruments' noise at level {}; \
             candidates by nested F-test at level {:.2e} (Bonferroni over {}), ranked by BIC gain \
             (n = {n_rows} rows)",
            opts.alpha,
            level,
            tried.len()
        ),
    })
}

fn verdict(
    base: &Baseline,
    best: Option<&Candidate>,
    candidates: &[Candidate],
    unexplained: Option<&sparse::Pointer>,
    in_model: &[&str],
) -> String {
    let model = if in_model.is_empty() {
        "the geometric model".to_owned()
    } else {
        format!("the model with {}", in_model.join(", "))
    };
    if base.consistent_with_noise {
        return format!(
            "nothing is missing: {model} explains the measurements to the instruments' noise \
             (chi2/dof {:.2}, p = {:.2})",
            base.chi2_per_dof, base.p_value
        );
    }
    match best {
        Some(c) => format!(
            "missing effect: {} ({}){}",
            c.effect,
            c.evidence,
            unexplained.map_or(String::new(), |u| format!("; what remains: {}", u.sentence))
        ),
        None => {
            let why = candidates.first().map_or(String::new(), |c| {
                format!(
                    " (the best, {}, explains {:.0} % of it)",
                    c.effect,
                    100.0 * c.explained_fraction
                )
            });
            format!(
                "{model} leaves a structured residual (chi2/dof {:.2}) that no effect of the \
                 library explains{why}; {}",
                base.chi2_per_dof,
                unexplained.map_or(
                    "no covariate, force, time or workspace term follows it".to_owned(),
                    |u| u.sentence.clone()
                )
            )
        }
    }
}

/// A fit that failed.
#[derive(Debug, thiserror::Error)]
enum FitError {
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
    #[error(transparent)]
    Effect(#[from] NotApplicable),
    #[error(transparent)]
    Validation(#[from] PoseError),
}

/// Calibrate `campaign` with `effects` in the model and evaluate it on the held-out data: the
/// statistics of one model, as the diagnosis compares them (`rpkm calibrate --effects`).
pub fn evaluate(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    effects: &[&dyn Effect],
    opts: &Options,
) -> Result<Fit, DiagnoseError> {
    let val = held_out(validation)?;
    Ok(fit(campaign, val.as_ref(), effects, &Params::nominal(), opts)?.fit)
}

/// The held-out campaign with the noise of each of its TCP errors.
fn held_out(validation: Option<&Campaign>) -> Result<Option<Validation<'_>>, DiagnoseError> {
    validation
        .map(|v| validation_noise(v).map(|sigma| Validation { campaign: v, sigma }))
        .transpose()
        .map_err(DiagnoseError::Validation)
}

impl From<FitError> for DiagnoseError {
    /// A failed fit of the model being diagnosed.
    fn from(e: FitError) -> Self {
        match e {
            FitError::Calibration(c) => DiagnoseError::Baseline(c),
            FitError::Effect(n) => DiagnoseError::Effect(n),
            FitError::Validation(v) => DiagnoseError::Validation(v),
        }
    }
}

/// Calibrate with `effects` and evaluate on the held-out data.
fn fit(
    campaign: &Campaign,
    val: Option<&Validation>,
    effects: &[&dyn Effect],
    start: &Params,
    opts: &Options,
) -> Result<Fitted, FitError> {
    let set = EffectSet::bind(effects, campaign, start)?;
    let copts = calib_options(opts);
    let cal = calib::calibrate_with(campaign, start, &copts, &set, &[])?;
    let corr = set.corrections(&cal.theta);
    let rows = obs::residuals_with(
        campaign,
        &cal.params,
        copts.model,
        Step::Direct,
        start,
        &corr,
    )?;
    let chi2: f64 = rows.iter().map(|r| (r.value / r.sigma).powi(2)).sum();
    let dof = rows.len().saturating_sub(cal.n_identified).max(1);
    let val_rms_um = val
        .map(|v| held_out_rms(v, effects, &set, &cal, copts.model))
        .transpose()?;
    let fit = Fit {
        chi2,
        dof,
        chi2_per_dof: chi2 / dof as f64,
        cal_rms_um: calib::rms(&length_values(&rows)) * 1e3,
        val_rms_um,
        effect_params: cal.effects.clone(),
        params: cal.params,
    };
    Ok(Fitted { rows, fit })
}

/// Calibration options of the diagnosis: the model's links, automatic selection, no outlier
/// elimination (the nested tests need the same rows in every fit).
pub fn calib_options(opts: &Options) -> calib::Options {
    calib::Options {
        model: Model::M29,
        selection: calib::Selection::Auto {
            max_condition: opts.max_condition,
        },
        links: match opts.model {
            Model::M24 => calib::Link::perfect_parallelogram(),
            Model::M29 => Vec::new(),
        },
        outlier_sigma: None,
        ..Default::default()
    }
}

/// RMS of the held-out TCP errors (mm → µm) with the calibrated model and effects; the
/// effects' setup-local parameters are re-fitted on the held-out setups (Gauss-Newton).
fn held_out_rms(
    val: &Validation,
    effects: &[&dyn Effect],
    cal_set: &EffectSet,
    cal: &Calibration,
    model: Model,
) -> Result<f64, FitError> {
    let set = EffectSet::bind(effects, val.campaign, &cal.params)?;
    let cal_layout = cal_set.layout();
    let layout = set.layout();
    // machine parameters carry over by name; setup-local ones start at zero
    let mut theta: Vec<f64> = layout
        .iter()
        .map(|(e, prm, _, local)| {
            if *local {
                return 0.0;
            }
            cal_layout
                .iter()
                .find(|(ce, cp, _, _)| ce == e && cp.name == prm.name)
                .map_or(0.0, |(_, _, k, _)| cal.theta[*k])
        })
        .collect();
    let local: Vec<usize> = layout.iter().filter(|l| l.3).map(|l| l.2).collect();
    let weights: Vec<f64> = val.sigma.iter().map(|s| 1.0 / s).collect();
    for _ in 0..if local.is_empty() { 0 } else { 5 } {
        let errs =
            obs::tcp_errors_with(val.campaign, &cal.params, model, &set.corrections(&theta))?;
        let j = DMatrix::from_fn(errs.len(), local.len(), |i, k| {
            errs[i].d_theta[local[k]] * weights[i]
        });
        let r = DVector::from_iterator(
            errs.len(),
            errs.iter().zip(&weights).map(|(e, w)| e.value * w),
        );
        let Some(step) = (j.transpose() * &j)
            .cholesky()
            .map(|c| c.solve(&(j.transpose() * r)))
        else {
            break;
        };
        for (k, &t) in local.iter().enumerate() {
            theta[t] -= step[k];
        }
    }
    let errs = obs::tcp_errors_with(val.campaign, &cal.params, model, &set.corrections(&theta))?;
    let v: Vec<f64> = errs.iter().map(|e| e.value).collect();
    Ok(calib::rms(&v) * 1e3)
}

/// σ of every held-out TCP error, in [`obs::tcp_errors`] order: the instrument's noise at the
/// pose (the reset pose reads 0 by definition).
fn validation_noise(val: &Campaign) -> Result<Vec<f64>, PoseError> {
    let nominal = Params::nominal();
    let errs = obs::tcp_errors(val, &nominal, Model::M29)?;
    errs.iter()
        .map(|(i, coordinate, _)| {
            let pose = &val.poses[*i];
            let tcp = geometry::fgm(&nominal, Model::M29, pose.q[0], pose.q[3])
                .map_err(|e| PoseError::at(val, pose, e))?;
            let cov = noise::xy_covariance(pose.instrument, Vector2::new(tcp.x(), tcp.y()));
            let enc = noise::ENCODER_MM;
            Ok(match (*coordinate, pose.instrument) {
                ("x", Instrument::Lt | Instrument::Kgm) => (cov[(0, 0)] + enc * enc).sqrt(),
                ("y", Instrument::Lt | Instrument::Kgm) => (cov[(1, 1)] + enc * enc).sqrt(),
                _ => (noise::scalar_sigma(pose.instrument).powi(2) + enc * enc).sqrt(),
            })
        })
        .collect()
}

/// The candidate's comparison with the current model; None if the effect added no parameter.
fn compare(
    base: &Fitted,
    with: &Fitted,
    effect: &str,
    covariates: &[&str],
    campaign: &Campaign,
    level: f64,
) -> Option<Candidate> {
    let k = base.fit.dof.saturating_sub(with.fit.dof);
    if k == 0 {
        return None;
    }
    let dchi2 = base.fit.chi2 - with.fit.chi2;
    let f = (dchi2 / k as f64) / (with.fit.chi2 / with.fit.dof as f64);
    let p_value = stats::f_upper_tail(f, k as f64, with.fit.dof as f64);
    let excess = base.fit.chi2 - base.fit.dof as f64;
    let explained_fraction = if excess > 0.0 {
        (dchi2 / excess).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let n = base.rows.len() as f64;
    let params: Vec<EffectEstimate> = with
        .fit
        .effect_params
        .iter()
        .filter(|e| e.effect == effect)
        .cloned()
        .collect();
    let evidence = evidence(base, with, covariates, campaign, &params, f, p_value);
    Some(Candidate {
        effect: effect.to_owned(),
        significant: p_value < level,
        explained_fraction,
        val_rms_before_um: base.fit.val_rms_um,
        val_rms_after_um: with.fit.val_rms_um,
        chi2_per_dof_after: with.fit.chi2_per_dof,
        f_statistic: f,
        f_dof: (k, with.fit.dof),
        p_value,
        bic_gain: dchi2 - k as f64 * n.ln(),
        params,
        evidence,
    })
}

fn evidence(
    base: &Fitted,
    with: &Fitted,
    covariates: &[&str],
    campaign: &Campaign,
    params: &[EffectEstimate],
    f: f64,
    p: f64,
) -> String {
    let shown: Vec<String> = params
        .iter()
        .filter(|e| e.identified)
        .take(3)
        .map(|e| format!("{} = {:.3} ± {:.3} {}", e.name, e.value, e.sigma, e.unit))
        .collect();
    let mut s = format!(
        "chi2/dof {:.2} -> {:.2}, F = {:.1} (p = {:.1e}); {}",
        base.fit.chi2_per_dof,
        with.fit.chi2_per_dof,
        f,
        p,
        shown.join(", ")
    );
    if let Some(c) = sparse::follows(campaign, &base.rows, covariates) {
        s.push_str(&format!("; {}", c.sentence));
    }
    if let (Some(b), Some(a)) = (base.fit.val_rms_um, with.fit.val_rms_um) {
        s.push_str(&format!("; held-out RMS {b:.1} -> {a:.1} um"));
    }
    s
}

/// Values (mm) of the length rows (not ψ).
fn length_values(rows: &[Residual]) -> Vec<f64> {
    rows.iter()
        .filter(|r| !r.direction.is_angle())
        .map(|r| r.value)
        .collect()
}

fn length_sigmas(rows: &[Residual]) -> Vec<f64> {
    rows.iter()
        .filter(|r| !r.direction.is_angle())
        .map(|r| r.sigma)
        .collect()
}

fn groups(rows: &[Residual]) -> Vec<GroupRms> {
    let mut acc: std::collections::BTreeMap<(String, String), (usize, f64, f64, f64)> =
        Default::default();
    for r in rows {
        let e = acc
            .entry((r.instrument.as_str().to_owned(), r.direction.to_string()))
            .or_default();
        e.0 += 1;
        e.1 += r.value * r.value;
        e.2 += r.sigma * r.sigma;
        e.3 += (r.value / r.sigma).powi(2);
    }
    acc.into_iter()
        .map(|((instrument, direction), (n, v, s, c))| GroupRms {
            instrument,
            direction,
            rows: n,
            rms: (v / n as f64).sqrt() * 1e3,
            noise: (s / n as f64).sqrt() * 1e3,
            chi2_per_row: c / n as f64,
        })
        .collect()
}

fn points(campaign: &Campaign, rows: &[Residual]) -> Vec<Point> {
    let tcp = sparse::nominal_tcp(campaign);
    let mut out: Vec<Point> = rows
        .iter()
        .map(|r| {
            let pose = &campaign.poses[r.pose];
            let (x, y) = tcp[r.pose];
            Point {
                pose: r.pose,
                line: pose.line,
                instrument: r.instrument.as_str().to_owned(),
                direction: r.direction.to_string(),
                x,
                y,
                t: pose.t,
                value: r.value * 1e3,
                sigma: r.sigma * 1e3,
            }
        })
        .collect();
    out.sort_by(|a, b| {
        (b.value / b.sigma)
            .abs()
            .total_cmp(&(a.value / a.sigma).abs())
    });
    out
}
