//! The held-out judge: a calibrated model's errors on poses it has not seen, the noise they
//! would have if the model were right, and whether they agree.
//!
//! One evaluation for every command and node ([`Model1::held_out_theta`], fitted once per model and
//! held-out campaign, and [`Model1::held_out`], under [`judge_calibration`] and the
//! diagnosis's `judge`; the figures in [`figures`]): the model's TCP
//! errors at the held-out poses with its effects (setup-local effect parameters re-fitted on
//! the held-out setups), raw and with each setup's zero removed (the reading a relative
//! setup was zeroed on is in all its readings, and no model predicts it), the floor noise
//! alone would give, and the floor of the calibrated model itself: the noise plus what the
//! calibration's own uncertainty predicts at those poses. The errors agree with the model
//! when their χ² against that floor is what noise gives (an F-test against the estimated
//! noise's own degrees of freedom) and when they follow nothing (the structure tests of
//! [`super::structure`] on the held-out residual, with the time since each setup's zero).

pub mod coverage;
pub mod figures;
pub mod poses;
pub(in crate::diagnose) mod validation;

use super::structure::Shape;
use super::types::{DiagnoseError, Fit, FitError, HeldOutCheck, Prediction, RmsUnit};
use crate::calib::{self, Calibration};
use crate::campaign::Campaign;
use crate::effects::{Effect, EffectSet};
use crate::noise::{Group, N_GROUPS};
use crate::obs::{self, group_sums, Direction, RowValue};
use crate::params::{Params, N_PARAMS};
use crate::stats;
use crate::units::um_from_mm;
use crate::variance::GroupNoise;
use figures::HeldOut;
use nalgebra::{DMatrix, DVector};
use validation::Validation;

/// The held-out judge on a calibration made outside a diagnosis (`rpkm calibrate`, the
/// calibrator node): the same errors, floors and tests as the diagnosis's baseline, for the
/// model with `effects` bound to the calibration's campaign as `cal_set`, the floor of the
/// noise `noise` estimated with it, at the diagnosis's level `alpha`.
pub fn judge_calibration(
    validation: &Campaign,
    noise: &crate::variance::NoiseEstimate,
    (effects, cal_set): (&[&dyn Effect], &EffectSet),
    cal: &Calibration,
    alpha: f64,
) -> Result<HeldOutCheck, DiagnoseError> {
    let val = Validation::new(validation, &noise.model).map_err(DiagnoseError::Validation)?;
    let model = Model1 {
        effects,
        cal_set,
        cal,
    };
    let refit = model.held_out_theta(&val)?;
    let held = model.held_out(&val, &refit)?;
    Ok(judge(
        &val,
        (&model, &refit),
        held,
        &noise.groups,
        &Levels::at(alpha),
    )?)
}

/// The effects of a calibrated model bound to the held-out campaign, and their θ there.
pub(crate) struct HeldOutTheta {
    set: EffectSet,
    theta: Vec<f64>,
}

/// A calibrated model as the held-out judge reads it.
pub(crate) struct Model1<'a> {
    pub effects: &'a [&'a dyn Effect],
    pub cal_set: &'a EffectSet,
    pub cal: &'a Calibration,
}

impl Model1<'_> {
    /// θ on the held-out campaign's layout `set`: machine parameters carried over by name
    /// (the family's, where a part is pinned: `thermal:rods`'s alpha_rods is `thermal`'s),
    /// setup-local ones at zero.
    fn carried_theta(&self, set: &EffectSet) -> Vec<f64> {
        let cal_layout = self.cal_set.layout();
        set.layout()
            .iter()
            .map(|slot| {
                // a nuisance of the calibration's campaign is not the held-out's
                if slot.setup_local || slot.param.anchor.is_some() {
                    return 0.0;
                }
                cal_layout
                    .iter()
                    .find(|c| c.effect == slot.effect && c.param.name == slot.param.name)
                    .map_or(0.0, |c| self.cal.theta[c.index])
            })
            .collect()
    }

    /// The model's held-out figures ([`HeldOut`]) with its held-out θ `refit`: the
    /// calibrated model and effects, the effects' setup-local parameters fitted on the
    /// held-out setups.
    pub fn held_out(&self, val: &Validation, refit: &HeldOutTheta) -> Result<HeldOut, FitError> {
        let errs = obs::tcp_errors_with(
            val.campaign,
            &self.cal.params,
            self.cal.model,
            &refit.set.corrections(&refit.theta, &self.cal.params),
        )?;
        Ok(HeldOut::of(
            &val.noise(),
            errs.iter().map(|e| e.value).collect(),
            refit.set.setup_local_params(),
        ))
    }

    /// The model's held-out figures, its held-out θ fitted for them alone.
    pub fn evaluate(&self, val: &Validation) -> Result<HeldOut, FitError> {
        self.held_out(val, &self.held_out_theta(val)?)
    }

    /// The effects bound to the held-out campaign and their θ (setup-local parts fitted):
    /// fitted once per model and held-out campaign, read by its errors and its floor.
    pub fn held_out_theta(&self, val: &Validation) -> Result<HeldOutTheta, FitError> {
        let (cal, model) = (self.cal, self.cal.model);
        let set = EffectSet::bind(self.effects, val.campaign, &cal.params)?;
        let mut theta = self.carried_theta(&set);
        // bound among the carried effects, as the calibration's last round was
        let set = match set.rebound(val.campaign, &cal.params, &theta) {
            Some(rebound) => rebound?,
            None => set,
        };
        let local: Vec<usize> = set
            .layout()
            .iter()
            .filter(|slot| slot.setup_local)
            .map(|slot| slot.index)
            .collect();
        // fitted to the errors as they are judged: each setup's zero removed (no parameter of
        // the model predicts the reading it was zeroed on), each in its own noise
        let weights: Vec<f64> = val
            .relative_sigma
            .iter()
            .map(|s| 1.0 / s.max(f64::MIN_POSITIVE))
            .collect();
        for _ in 0..if local.is_empty() { 0 } else { 5 } {
            let errs = obs::tcp_errors_with(
                val.campaign,
                &cal.params,
                model,
                &set.corrections(&theta, &cal.params),
            )?;
            let columns: Vec<Vec<f64>> = local
                .iter()
                .map(|&k| val.relative(&errs.iter().map(|e| e.d_theta[k]).collect::<Vec<_>>()))
                .collect();
            let j = DMatrix::from_fn(errs.len(), local.len(), |i, k| columns[k][i] * weights[i]);
            let values = val.relative(&errs.iter().map(|e| e.value).collect::<Vec<_>>());
            let r =
                DVector::from_iterator(errs.len(), values.iter().zip(&weights).map(|(e, w)| e * w));
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
        Ok(HeldOutTheta { set, theta })
    }

    /// The covariance (mm²) the calibration's own uncertainty gives the held-out errors with
    /// their setups' zeros removed, J Σ Jᵀ in full: errors near each other share it.
    fn prediction_covariance(
        &self,
        val: &Validation,
        refit: &HeldOutTheta,
    ) -> Result<DMatrix<f64>, FitError> {
        let (rel, cov) = self.sensitivities(val, refit)?;
        Ok(&rel * cov * rel.transpose())
    }

    /// The held-out errors' sensitivities to the calibrated parameters and to the held-out
    /// campaign's own nuisances (each less its setup's mean), and the covariance of those:
    /// the calibration's, and the nuisances' priors.
    fn sensitivities(
        &self,
        val: &Validation,
        refit: &HeldOutTheta,
    ) -> Result<(DMatrix<f64>, DMatrix<f64>), FitError> {
        let (cal, model) = (self.cal, self.cal.model);
        let HeldOutTheta { set, theta } = refit;
        // the corrections at each p: a binding that reads the geometry changes with it
        let at =
            |p: &Params| obs::tcp_errors_with(val.campaign, p, model, &set.corrections(theta, p));
        let base = at(&cal.params)?;
        let n = base.len();
        let layout = set.layout();
        let cal_layout = self.cal_set.layout();
        // the held-out θ's places in the calibration's θ (machine parameters only)
        let carried: Vec<(usize, usize)> = layout
            .iter()
            .filter(|s| !s.setup_local && s.param.anchor.is_none())
            .filter_map(|s| {
                cal_layout
                    .iter()
                    .find(|c| c.effect == s.effect && c.param.name == s.param.name)
                    .map(|c| (s.index, c.index))
            })
            .collect();
        // the held-out campaign's own nuisances (a thermometer's error modes there), at zero
        // in θ: their priors are as much a part of the prediction's uncertainty
        let own: Vec<(usize, f64)> = layout
            .iter()
            .filter_map(|s| s.param.anchor.map(|sigma| (s.index, sigma)))
            .collect();
        let m = N_PARAMS + carried.len() + own.len();
        let mut j = DMatrix::zeros(n, m);
        for i in 0..N_PARAMS {
            if cal.covariance[(i, i)] <= 0.0 {
                continue;
            }
            let h = match crate::params::unit(i) {
                crate::params::Unit::Rad => 1e-7,
                crate::params::Unit::Mm => 1e-4,
            };
            let (mut up, mut down) = (cal.params, cal.params);
            up[i] += h;
            down[i] -= h;
            let (eu, ed) = (at(&up)?, at(&down)?);
            for r in 0..n {
                j[(r, i)] = (eu[r].value - ed[r].value) / (2.0 * h);
            }
        }
        let effect_params = carried.iter().map(|c| c.0).chain(own.iter().map(|o| o.0));
        for (c, k) in effect_params.enumerate() {
            for r in 0..n {
                j[(r, N_PARAMS + c)] = base[r].d_theta.get(k).copied().unwrap_or(0.0);
            }
        }
        let cov = covariance(cal, &carried, &own);
        // each error less its setup's mean, in the sensitivities alike
        let mut rel = j.clone();
        let count = group_sums(&val.zero, &vec![1.0; n]);
        for col in 0..m {
            let column: Vec<f64> = (0..n).map(|r| j[(r, col)]).collect();
            let sum = group_sums(&val.zero, &column);
            for r in 0..n {
                let g = val.zero[r];
                rel[(r, col)] -= sum[g].0 / count[g].1.max(1) as f64;
            }
        }
        Ok((rel, cov))
    }
}

/// The covariance of the parameters a held-out prediction reads: the geometry and the
/// `carried` effect parameters ((held-out index, calibration index)) as the calibration
/// estimated them, then the held-out campaign's `own` nuisances ((index, σ)) at their priors,
/// independent of the rest.
fn covariance(cal: &Calibration, carried: &[(usize, usize)], own: &[(usize, f64)]) -> DMatrix<f64> {
    let m = N_PARAMS + carried.len() + own.len();
    let mut cov = DMatrix::zeros(m, m);
    for a in 0..N_PARAMS {
        for b in 0..N_PARAMS {
            cov[(a, b)] = cal.covariance[(a, b)];
        }
    }
    for (c, &(_, kc)) in carried.iter().enumerate() {
        for a in 0..N_PARAMS {
            let v = cal.covariance_p_theta.get((a, kc)).copied().unwrap_or(0.0);
            cov[(a, N_PARAMS + c)] = v;
            cov[(N_PARAMS + c, a)] = v;
        }
        for (d, &(_, kd)) in carried.iter().enumerate() {
            cov[(N_PARAMS + c, N_PARAMS + d)] =
                cal.covariance_theta.get((kc, kd)).copied().unwrap_or(0.0);
        }
    }
    for (c, &(_, sigma)) in own.iter().enumerate() {
        let at = N_PARAMS + carried.len() + c;
        cov[(at, at)] = sigma * sigma;
    }
    cov
}

/// Levels of the held-out tests: the χ² against the floor (one test, at the diagnosis's
/// level), and each structure test (a third of it).
pub struct Levels {
    pub variance: f64,
    pub structure: f64,
}

impl Levels {
    /// The levels at the diagnosis's level `alpha`: the χ² at it, each of the three
    /// structure tests at a third of it (the family's level stays `alpha`). The one rule.
    pub fn at(alpha: f64) -> Levels {
        Levels {
            variance: alpha,
            structure: alpha / 3.0,
        }
    }
}

/// The held-out judge on a calibrated model with its held-out θ `refit` and its figures
/// `held`: its floors and test; `groups`: the noise estimate the floor is made of (its
/// degrees of freedom per group).
pub(crate) fn judge(
    val: &Validation,
    (model, refit): (&Model1, &HeldOutTheta),
    held: HeldOut,
    groups: &[GroupNoise],
    levels: &Levels,
) -> Result<HeldOutCheck, FitError> {
    let relative = &held.errors.relative;
    let pc = model.prediction_covariance(val, refit)?;
    let pv: Vec<f64> = pc.diagonal().iter().map(|v| v.max(0.0)).collect();
    let n = relative.len();
    let var: Vec<f64> = val
        .relative_sigma
        .iter()
        .zip(&pv)
        .map(|(s, p)| s * s + p)
        .collect();
    let noise: Vec<f64> = val.relative_sigma.iter().map(|s| s * s).collect();
    let beyond = beyond_calibration(noise, relative, &pc);
    // the calibration's uncertainty is one error shared by neighbouring poses, not one per
    // pose: a 2σ error of the tracker-blind expansion put 2σ into every held-out pose, which
    // the diagonal counted as hundreds of independent 2σ draws (p = 1.7e-10 on the true model)
    let chi2 = beyond.chi2.unwrap_or_else(|| {
        relative
            .iter()
            .zip(&var)
            .filter(|(_, v)| **v > 0.0)
            .map(|(e, v)| e * e / v)
            .sum()
    });
    let dof = (n as f64 - val.n_groups() as f64).max(1.0);
    let statistic = chi2 * dof / (n.max(1) as f64);
    let noise_dof = floor_dof(val, &var, groups);
    let p_value = if noise_dof.is_finite() {
        stats::f_upper_tail(statistic / dof, dof, noise_dof)
    } else {
        stats::chi2_upper_tail(statistic, dof)
    };
    let rows = held_out_rows(val, &beyond.own, &beyond.noise);
    let shape = Shape::of(val.campaign, &rows, levels.structure);
    let dictionary = shape.dictionary.clone();
    let structured = shape.structured();
    Ok(HeldOutCheck {
        floor_relative: (var.iter().sum::<f64>() / n.max(1) as f64).sqrt(),
        statistic,
        dof,
        noise_dof,
        p_value,
        consistent: p_value >= levels.variance,
        structure_p: shape.smallest_p(),
        structured,
        follows: structured.then(|| dictionary.pointer.clone()).flatten(),
        nuisance_terms: refit
            .set
            .layout()
            .iter()
            .filter(|s| s.param.anchor.is_some())
            .count(),
        figures: held,
    })
}

/// The floor's degrees of freedom (Satterthwaite): each noise group's share of the floor
/// with the degrees of freedom of its estimate (a stated level counts as known), the
/// calibration's own share as known.
fn floor_dof(val: &Validation, var: &[f64], groups: &[GroupNoise]) -> f64 {
    let mut share = [0.0; N_GROUPS];
    for (parts, v) in val.relative_parts.iter().zip(var) {
        if *v > 0.0 {
            for k in 0..N_GROUPS {
                share[k] += parts[k] / v;
            }
        }
    }
    let total: f64 = var.iter().filter(|v| **v > 0.0).count() as f64;
    let mut spread = 0.0;
    for (k, g) in Group::ALL.iter().enumerate() {
        let estimated = groups
            .iter()
            .find(|e| e.group == g.name() && e.estimated_from_data);
        if let Some(e) = estimated {
            spread += share[k] * share[k] / e.dof.max(1.0);
        }
    }
    if spread > 0.0 {
        total * total / spread
    } else {
        f64::INFINITY
    }
}

/// The held-out errors against the calibration's own uncertainty in full (V = P + the
/// readings' noise, P = J Σ Jᵀ).
struct Beyond {
    /// The errors less what that uncertainty most likely put there (r − P V⁻¹ r), and the
    /// noise's variances: a calibration's parameter error is smooth over the poses and would
    /// read as structure (a self-calibration leaves the tracker's poses a y² its scale cannot
    /// fix).
    own: Vec<f64>,
    noise: Vec<f64>,
    /// rᵀ V⁻¹ r. None where V cannot be factored (`own` then the errors as they are).
    chi2: Option<f64>,
}

fn beyond_calibration(noise: Vec<f64>, relative: &[f64], pc: &DMatrix<f64>) -> Beyond {
    let n = relative.len();
    let as_they_are = |noise| Beyond {
        own: relative.to_vec(),
        noise,
        chi2: None,
    };
    if pc.nrows() != n || noise.len() != n {
        return as_they_are(noise);
    }
    let mut v = pc.clone();
    for (k, s2) in noise.iter().enumerate() {
        v[(k, k)] += s2;
    }
    let r = nalgebra::DVector::from_column_slice(relative);
    match v.cholesky() {
        Some(c) => {
            let x = c.solve(&r);
            Beyond {
                own: (0..n).map(|k| noise[k] * x[k]).collect(),
                chi2: Some(r.dot(&x)),
                noise,
            }
        }
        None => as_they_are(noise),
    }
}

/// The held-out errors as residual rows (each in its floor's σ): what the structure tests
/// read.
fn held_out_rows(val: &Validation, relative: &[f64], var: &[f64]) -> Vec<RowValue> {
    val.at
        .iter()
        .zip(relative.iter().zip(var))
        .map(|(&(pose, coordinate), (&e, &v))| RowValue {
            pose,
            instrument: val.campaign.poses[pose].instrument,
            direction: match coordinate {
                "x" => Direction::X(0, 3),
                "y" => Direction::Y(0, 3),
                _ => Direction::R(0, 3),
            },
            value: e,
            sigma: v.sqrt(),
            parts: [0.0; N_GROUPS],
        })
        .collect()
}

impl Prediction {
    /// The comparison of the held-out TCP errors `before` and `after` (mm, the same poses in
    /// the same order); None without poses.
    pub fn of(before: &[f64], after: &[f64]) -> Option<Prediction> {
        Self::compared(before, after).map(|p| Prediction {
            rms_before: um_from_mm(p.rms_before),
            rms_after: um_from_mm(p.rms_after),
            standard_error: um_from_mm(p.standard_error),
            unit: RmsUnit::Um,
            ..p
        })
    }

    /// The held-out comparison of two fits of one round as a user reads it: the RMS (µm,
    /// each setup's zero removed), its standard error, better or worse; with the support
    /// [`Prediction::scaled`] judges in the errors' own noise. None without held-out data.
    pub(crate) fn held_out(before: &Fit, after: &Fit) -> Option<Prediction> {
        let judged = Self::scaled(before, after)?;
        let (b, a) = (before.held_out.as_ref()?, after.held_out.as_ref()?);
        Self::of(&b.errors.relative, &a.errors.relative).map(|p| Prediction {
            support_p: judged.support_p,
            refitted: judged.refitted,
            ..p
        })
    }

    /// The held-out comparison of two fits of one round as models are judged: its support
    /// and size in the errors' own noise (σ); whether it is better or worse, which decides
    /// whether the held-out data have their say or the setups left out do, on the TCP
    /// errors in µm, as the user reads them (in σ a tie sent a soft rod's frame expansion
    /// to the left-out setups, which share the calibration's misfit and named it). None
    /// without held-out data.
    pub(crate) fn scaled(before: &Fit, after: &Fit) -> Option<Prediction> {
        let (b, a) = (before.held_out.as_ref()?, after.held_out.as_ref()?);
        let n = a.scaled.len();
        let read = Self::compared(&b.errors.relative, &a.errors.relative)?;
        Self::compared(&b.scaled, &a.scaled).map(|p| Prediction {
            better: read.better,
            worse: read.worse,
            fall_read: read.fall_read,
            ..p.refit(a.refit.saturating_sub(b.refit), n)
        })
    }

    /// This comparison where the larger model has `k` more parameters fitted with the `n`
    /// errors compared themselves (an alignment refitted on the held-out setup; a left-out
    /// setup's own angle, the whole fit's): its change follows them by construction, so its
    /// support is the fall of their mean square (in σ) beyond the k/n that fitting k
    /// parameters to noise takes, in the fall's standard error. Conservative on noise (a
    /// fitted change's fall is smallest where its standard error is), and not a χ² test of
    /// the gain: held-out errors carry the calibration's own smooth uncertainty, part of
    /// which a refitted angle takes beyond what independent noise would give.
    #[must_use]
    pub fn refit(self, k: usize, n: usize) -> Prediction {
        if k == 0 {
            return self;
        }
        let (b, a) = (self.rms_before, self.rms_after);
        let beyond = b * b - a * a - k as f64 / n.max(1) as f64;
        let z = beyond / (self.standard_error * (b + a));
        Prediction {
            support_p: if z.is_nan() {
                1.0
            } else {
                stats::normal_upper_tail(z)
            },
            refitted: k,
            ..self
        }
    }

    /// The comparison of errors in any one unit (left-out rows in σ: `unit` sigma).
    pub fn compared(before: &[f64], after: &[f64]) -> Option<Prediction> {
        let n = before.len();
        if n < 2 || after.len() != n {
            return None;
        }
        let d: Vec<f64> = before
            .iter()
            .zip(after)
            .map(|(b, a)| b * b - a * a)
            .collect();
        let mean = d.iter().sum::<f64>() / n as f64;
        let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        let (rb, ra) = (calib::rms(before), calib::rms(after));
        // the RMS's fall and its error through d(RMS²) = (RMS_b + RMS_a) d(RMS)
        let se = (var / n as f64).sqrt() / (rb + ra).max(f64::MIN_POSITIVE);
        Some(Prediction {
            rms_before: rb,
            rms_after: ra,
            standard_error: se,
            unit: RmsUnit::Sigma,
            support_p: support(before, after),
            refitted: 0,
            better: rb - ra > se,
            worse: ra - rb > 2.0 * se,
            fall_read: rb - ra,
            by_setup: false,
            resolution: resolution(before, after),
        })
    }

    /// Whether the compared errors decide between the two models: the RMS clearly falls or
    /// rises. Where they do not, the setups left out do.
    pub fn decides(&self) -> bool {
        self.better || self.worse
    }

    /// Whether the compared errors have the last word on the change: they decide it
    /// ([`Prediction::decides`]) or contradict it ([`Prediction::contradicted`]). Where they do
    /// not, the setups left out are asked. One rule for a candidate against the current model,
    /// a model against another, and a family's parts against the whole.
    pub fn last_word(&self) -> bool {
        self.decides() || self.contradicted()
    }

    /// Whether the compared errors contradict the change: they resolve it (were it right,
    /// they would follow it at [`RESOLVED`] standard errors or more), do not follow it (its
    /// support's p-value at least [`NOT_FOLLOWED`]) and their RMS, read as the user reads it,
    /// does not fall (a soft rod's preload lowered a noisy tracker's 29.73 to 29.46 µm, not
    /// followed at p = 0.099 in σ, and the setups left out confirmed it). There a candidate's
    /// held-out data have the last word even where their RMS neither clearly falls nor
    /// rises: the left-out setups share the
    /// calibration's misfit, and on the foreign `soft_rod` they supported a frame expansion
    /// (1.42 -> 1.14 σ) that the held-out tracker resolved at 4.9 and did not follow
    /// (0.82 -> 0.89 σ, p = 0.45). A change fitted to the compared errors themselves
    /// (`refitted`) follows them by construction and is never contradicted this way.
    pub fn contradicted(&self) -> bool {
        self.refitted == 0
            && self.resolution >= RESOLVED
            && self.support_p >= NOT_FOLLOWED
            && self.fall_read <= 0.0
    }

    /// RMS of the part of the errors the change explains, √(RMS_b² − RMS_a²), in `unit`
    /// (0 where it explains nothing).
    pub fn explained(&self) -> f64 {
        (self.rms_before.powi(2) - self.rms_after.powi(2))
            .max(0.0)
            .sqrt()
    }
}

/// The expected t-value of the held-out regression on a change, were it right, from which
/// the held-out data resolve it ([`Prediction::contradicted`]): four standard errors, where
/// a right change reads below [`NOT_FOLLOWED`] in 0.9 % (N(4, 1) below 1.64).
pub const RESOLVED: f64 = 4.0;

/// The support's p-value from which resolved errors do not follow a change (z below 1.64).
pub const NOT_FOLLOWED: f64 = 0.05;

/// The change from `before` to `after` over the errors' RMS (see
/// [`Prediction::resolution`]).
fn resolution(before: &[f64], after: &[f64]) -> f64 {
    let size = before
        .iter()
        .zip(after)
        .map(|(b, a)| (b - a) * (b - a))
        .sum::<f64>()
        .sqrt();
    let s = calib::rms(before);
    if s > 0.0 {
        size / s
    } else {
        0.0
    }
}

/// The one-sided p-value of the t-value of `before` regressed on the change to `after`
/// (Δ = before − after, what the larger model takes away): Σ bΔ / (s √ΣΔ²), with s the
/// errors' own RMS (not their rated noise: a model that misses something else leaves more,
/// and the test must not read that excess as support). 1 where nothing changes.
fn support(before: &[f64], after: &[f64]) -> f64 {
    let (mut follow, mut size) = (0.0, 0.0);
    for (b, a) in before.iter().zip(after) {
        let change = b - a;
        follow += b * change;
        size += change * change;
    }
    let scale = calib::rms(before) * size.sqrt();
    if scale > 0.0 {
        stats::normal_upper_tail(follow / scale)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A calibration error shared by every held-out pose (P = u uᵀ, one mode) is one draw,
    /// not one per pose: rᵀ V⁻¹ r against Sherman-Morrison's rᵀR⁻¹r − (uᵀR⁻¹r)²/(1 + uᵀR⁻¹u),
    /// and the errors less that mode's most likely share, r − P V⁻¹ r. Errors that are 2σ of
    /// the mode at every pose count about 4 (the one 2σ draw), where the diagonal counted
    /// hundreds.
    #[test]
    fn a_shared_calibration_error_counts_once() {
        let n = 200;
        let noise: Vec<f64> = (0..n).map(|k| 1.0 + 0.5 * (k % 3) as f64).collect();
        let u: Vec<f64> = (0..n).map(|k| 3.0 * (1.0 + k as f64 / n as f64)).collect();
        let p = DMatrix::from_fn(n, n, |a, b| u[a] * u[b]);
        let relative: Vec<f64> = (0..n)
            .map(|k| 2.0 * u[k] + if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let beyond = beyond_calibration(noise.clone(), &relative, &p);
        let rr: f64 = relative.iter().zip(&noise).map(|(r, s)| r * r / s).sum();
        let ur: f64 = (0..n).map(|k| u[k] * relative[k] / noise[k]).sum();
        let uu: f64 = (0..n).map(|k| u[k] * u[k] / noise[k]).sum();
        let want = rr - ur * ur / (1.0 + uu);
        let chi2 = beyond.chi2.expect("V factors");
        assert!((chi2 - want).abs() < 1e-9 * want, "{chi2} vs {want}");
        // the ±1 alternation is the noise: ~n/1.6 of it, plus the mode's one 2σ draw (the
        // diagonal, Σ r²/(R + u²), reads these errors as over 3n)
        assert!(chi2 < 0.75 * n as f64 + 10.0, "{chi2}");
        // what is left is the noise's share: P V⁻¹ r = u (uᵀR⁻¹r)/(1 + uᵀR⁻¹u)
        let share = ur / (1.0 + uu);
        for k in 0..n {
            let want = relative[k] - u[k] * share;
            assert!((beyond.own[k] - want).abs() < 1e-9, "pose {k}");
        }
    }
}
