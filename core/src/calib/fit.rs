//! One fit of a request: the plan, step 1 with its outlier rounds, step 2 for the forward
//! instruments, the posterior and the report.

use super::lm::{Final, Keep, Lm};
use super::plan::{before_table, Plan};
use super::progress::Observer;
use super::report;
use super::request::{Noise, Request};
use super::rows::{dependency, reduced_jacobian, Columns, Key, Problem};
use super::select::auto_select;
use super::select::{prior_of, scaling_vector};
use super::shared::View;
use super::types::{
    Calibration, CalibrationError, EffectEstimate, Identified, Options, Outlier, Selection, State,
};
use super::uncertainty::{posterior, step2_covariance, Posterior, KEEP_JACOBIAN_POSES};
use crate::campaign::Campaign;
use crate::effects::{Corrections, EffectSet};
use crate::obs::{Residual, RowValue, Step};
use crate::params::{Model, Params, NAMES, N_PARAMS};
use nalgebra::{DMatrix, DVector, SMatrix};
use std::cell::OnceCell;
use std::collections::HashSet;

/// One fit as `req` asks, its rows weighted by `req.options.noise` (the noise rounds of
/// [`super::Noise::Estimate`] make one each), with the rows at the start and the warm start read
/// from `req.shared` where they are there.
pub(super) fn fit_once(req: &Request) -> Result<Calibration, CalibrationError> {
    // a nuisance that multiplies another parameter (a thermometer's rate error, the lag)
    // moves nothing while that one is zero: fitted from where the rest is, not together
    if let Some(held) = req.effects.without_anchored() {
        let first = fit_plain(&Request {
            effects: &held,
            ..*req
        })?;
        return fit_plain(&Request {
            warm: Some(super::types::WarmStart {
                params: &first.params,
                theta: &first.theta,
                screen: false,
            }),
            shared: None,
            ..*req
        });
    }
    fit_plain(req)
}

fn fit_plain(req: &Request) -> Result<Calibration, CalibrationError> {
    let Request {
        campaign,
        start,
        options: opts,
        effects,
        theta0,
        warm,
        shared,
        progress,
        ..
    } = *req;
    let theta0 = start_theta(campaign, opts, effects, theta0)?;
    let pb = Problem::new(campaign, *start, effects, opts);
    let init = start_state(req, &theta0)?;
    // rows shared with other calibrations serve a warm start only (a cold one starts from
    // the plan's)
    let view = shared
        .filter(|_| warm.is_some())
        .and_then(|s| s.view(&pb, &theta0, &init));
    let mut plan = Plan::new(&pb, &theta0, warm.is_none(), view.as_ref())?;
    let (fit, last) = step1(
        &pb,
        &plan,
        init,
        (warm.is_some(), warm.is_some_and(|w| w.screen)),
        view.as_ref(),
        progress,
    )?;
    // the corrections at the fit's θ: only a large campaign's leverages and step 2 read them
    let corr = OnceCell::new();
    let corr = || corr.get_or_init(|| effects.corrections(&fit.state.theta, &fit.state.p));
    let leverages = req.leverages || matches!(req.noise, Noise::Estimate { .. });
    let (rows_final, post) = posterior(
        &pb,
        &plan,
        (&fit.state.p, &corr, &fit.drop),
        (last, leverages),
    )?;
    // chi-square of the measurements themselves (not the prior, nor the virtual rows of step 2)
    let chi2: f64 = rows_final.iter().map(|r| (r.value / r.sigma).powi(2)).sum();
    let chi2_per_dof = chi2 / (rows_final.len() as f64 - post.dof_model).max(1.0);
    let s1 = Step1Report::new(&pb, &plan, &fit.state, &post, chi2_per_dof.max(1.0));
    let mut table = step1_table(&pb, &mut plan, &fit.drop, &rows_final)?;
    let mut identified = s1.identified;
    let mut iterations = fit.iterations;
    let mut p = fit.state.p;
    // symmetric to the bit: the inverse's round-off is not the campaign's
    let mut covariance = SMatrix::<f64, N_PARAMS, N_PARAMS>::from_fn(|i, j| {
        0.5 * (s1.cov_p1[(i, j)] + s1.cov_p1[(j, i)])
    });
    if let Some(s2) = step2(&pb, &plan, &fit, &corr, &s1.cov_p1, progress)? {
        p = s2.p;
        iterations += s2.iterations;
        s2.widen(&mut covariance);
        identified.extend(s2.identified);
        table.before(s2.before_rows.iter().map(RowValue::from));
        table.after(s2.after_rows.iter().map(RowValue::from));
    }
    check_finite(&identified, &s1.effects, chi2_per_dof)?;
    Ok(Calibration {
        model: opts.model,
        start: *start,
        params: p,
        identified,
        iterations,
        screened: fit.screened,
        condition_number: plan.condition,
        outliers: fit.outliers,
        rms: table.finish(),
        cost_before: table.cost_before,
        cost_after: table.cost_after,
        chi2_per_dof,
        rows: table.rows,
        effects: s1.effects,
        theta: fit.state.theta,
        n_identified: plan.ids.len() + plan.free_theta.len(),
        dof_model: post.dof_model,
        determined: post.determined,
        residuals: rows_final,
        leverage: post.leverage,
        covariance,
        covariance_theta: s1.cov_theta,
        covariance_p_theta: s1.cov_p_theta,
    })
}

/// Where the LM starts: the warm start where the request gives one, else the start
/// parameters and θ₀.
fn start_state(req: &Request, theta0: &[f64]) -> Result<State, CalibrationError> {
    Ok(match req.warm {
        Some(w) => State {
            p: *w.params,
            theta: start_theta(req.campaign, req.options, req.effects, w.theta)?,
        },
        None => State {
            p: *req.start,
            theta: theta0.to_vec(),
        },
    })
}

/// The RMS table of step 1: its final rows, and the rows at the start, which are the plan's
/// unless outliers (`drop`) were dropped since.
pub(super) fn step1_table(
    pb: &Problem,
    plan: &mut Plan,
    drop: &HashSet<Key>,
    rows_final: &[RowValue],
) -> Result<report::RmsTable, CalibrationError> {
    let mut table = report::RmsTable::default();
    table.after(rows_final.iter().cloned());
    let before = if drop.is_empty() {
        std::mem::take(&mut plan.before)
    } else {
        let start = &pb.start;
        pb.map_pieces(
            Step::Direct,
            start,
            start,
            plan.corr0(pb),
            drop,
            before_table,
        )?
    };
    for t in before {
        table.merge(t);
    }
    Ok(table)
}

/// A calibration whose values, uncertainties or χ² are not finite is refused, naming what:
/// a solver reports an implausible result instead of returning it.
pub(super) fn check_finite(
    identified: &[Identified],
    effects: &[EffectEstimate],
    chi2_per_dof: f64,
) -> Result<(), CalibrationError> {
    if !chi2_per_dof.is_finite() {
        return Err(CalibrationError::NonFinite(format!(
            "chi2/dof {chi2_per_dof}"
        )));
    }
    let bad = identified
        .iter()
        .filter(|i| !(i.value.is_finite() && i.sigma.is_finite()))
        .map(|i| format!("{} = {} ± {}", i.name, i.value, i.sigma))
        .chain(
            effects
                .iter()
                .filter(|e| !(e.value.is_finite() && e.sigma.is_finite()))
                .map(|e| format!("{}.{} = {} ± {}", e.effect, e.name, e.value, e.sigma)),
        )
        .collect::<Vec<_>>();
    if bad.is_empty() {
        Ok(())
    } else {
        Err(CalibrationError::NonFinite(bad.join(", ")))
    }
}

/// The effect parameters to start from (`theta0`, each parameter's own start when it is
/// empty, [`crate::effects::EffectParam::start`]: zero for most; any other
/// length is an error), after checking that the options and the effects fit the campaign.
pub(super) fn start_theta(
    campaign: &Campaign,
    opts: &Options,
    effects: &EffectSet,
    theta0: &[f64],
) -> Result<Vec<f64>, CalibrationError> {
    if let Selection::List(list) = &opts.selection {
        if let Some(&i) = list.iter().find(|&&i| !opts.model.has_param(i)) {
            return Err(CalibrationError::NotInModel(NAMES[i], opts.model));
        }
    }
    if !effects.fits_campaign_of(campaign.poses.len()) {
        return Err(CalibrationError::EffectsOfAnotherCampaign {
            campaign: campaign.source.clone(),
            bound: effects.n_poses(),
            poses: campaign.poses.len(),
        });
    }
    if opts.model == Model::M24 {
        let probe = vec![1.0; effects.n_params()];
        if let Some(k) = effects.corrections(&probe, &Params::nominal()).rod5_apart() {
            let slot = &effects.layout()[k];
            return Err(CalibrationError::Rod5OfItsOwn {
                effect: slot.effect.clone(),
                why: format!("its {} changes rod 5 by its own amount", slot.param.name),
            });
        }
    }
    match theta0.len() {
        0 => Ok(effects.layout().iter().map(|s| s.param.start).collect()),
        n if n == effects.n_params() => Ok(theta0.to_vec()),
        given => Err(CalibrationError::StartThetaLength {
            given,
            expected: effects.n_params(),
        }),
    }
}

/// Step 1's fit: the unknowns, the rows dropped as outliers, the LM's iterations.
pub(super) struct Step1Fit {
    state: State,
    iterations: usize,
    /// The LM stopped after a confirmed screening step (see [`WarmStart::screen`]).
    screened: bool,
    drop: HashSet<Key>,
    outliers: Vec<Outlier>,
}

/// Step 1 with outlier elimination rounds (eq. 3.31-3.32): fit, drop the rows beyond
/// `outlier_sigma`, fit again, while new outliers appear and fewer than 5 % are dropped.
/// With the fit, the rows it ended with (the LM's last evaluation: the posterior's rows).
pub(super) fn step1(
    pb: &Problem,
    plan: &Plan,
    init: State,
    (warm, screen): (bool, bool),
    shared: Option<&View>,
    progress: Option<Observer>,
) -> Result<(Step1Fit, Final), CalibrationError> {
    let opts = pb.opts;
    let mut fit = Step1Fit {
        state: init,
        iterations: 0,
        screened: false,
        drop: HashSet::new(),
        outliers: Vec::new(),
    };
    // a small campaign keeps its final rows' Jacobian for the leverages
    let keep = if pb.campaign.poses.len() <= KEEP_JACOBIAN_POSES {
        Keep::Jacobians
    } else {
        Keep::Nothing
    };
    let last = loop {
        // the first run starts where the plan's rows (or the shared ones) were evaluated:
        // the start (cold) or the warm start, θ₀, nothing dropped
        let first = fit.drop.is_empty() && fit.iterations == 0;
        let lm = Lm {
            problem: pb,
            step: Step::Direct,
            p_cal: pb.start,
            drop: &fit.drop,
            d: dependency(&plan.ids, &opts.links),
            h: plan.h.clone(),
            free_theta: &plan.free_theta,
            h_theta: plan.h_theta.clone(),
            max_iterations: opts.max_iterations,
            screen,
            warm,
            prior: plan.prior.clone(),
            center: pb.start,
            theta_prior: plan.theta_prior.clone(),
            keep,
            initial: (!warm && first).then(|| plan.normal0.clone()).flatten(),
            // the first run at a warm start reads its start from shared rows, if any
            shared: shared.filter(|_| warm && first),
            made: shared
                .is_none()
                .then(|| (plan.theta0.as_slice(), plan.corr0(pb))),
        };
        let res = lm.run(&fit.state, progress)?;
        fit.state = res.state;
        fit.iterations += res.iterations;
        fit.screened = res.screened;
        // the rows the LM ended with (evaluated once more where it kept none): the outlier
        // test's and the posterior's
        let last = match res.last {
            Some(last) => last,
            None => lm.final_rows(&fit.state)?,
        };
        let found = opts
            .outlier_sigma
            .map(|k| report::find_outliers(&last.rows, pb.campaign, k));
        let Some(found) = found else { break last };
        if found.is_empty() || fit.outliers.len() > plan.n_rows0 / 20 {
            break last;
        }
        for (key, o) in found {
            fit.drop.insert(key);
            fit.outliers.push(o);
        }
    };
    Ok((fit, last))
}

/// Step 1's parameters with their uncertainties (scaled by the variance factor `s2`), and
/// the covariance of the 29 parameters step 2 inherits.
pub(super) struct Step1Report {
    identified: Vec<Identified>,
    effects: Vec<EffectEstimate>,
    cov_p1: DMatrix<f64>,
    /// The 29 parameters' covariance with every effect parameter (29 × θ) and the effect
    /// parameters' own (θ × θ); zero for a parameter held.
    cov_p_theta: DMatrix<f64>,
    cov_theta: DMatrix<f64>,
}

impl Step1Report {
    fn new(pb: &Problem, plan: &Plan, x: &State, post: &Posterior, s2: f64) -> Step1Report {
        let cov1 = &post.cov1 * s2;
        let d1 = dependency(&plan.ids, &pb.opts.links);
        let identified = plan
            .ids
            .iter()
            .enumerate()
            .map(|(k, &i)| Identified {
                name: NAMES[i],
                index: i,
                nominal: pb.start[i],
                value: x.p[i],
                sigma: cov1[(k, k)].max(0.0).sqrt(),
                step: 1,
            })
            .collect();
        let effects = pb
            .effects
            .layout()
            .iter()
            .enumerate()
            .map(|(k, slot)| {
                let free = plan.free_theta.iter().position(|&f| f == k);
                EffectEstimate {
                    effect: slot.effect.clone(),
                    name: slot.param.name.clone(),
                    unit: slot.param.unit.clone(),
                    value: x.theta[k],
                    sigma: free.map_or(0.0, |f| post.sig_theta[f] * s2.sqrt()),
                    observability: plan.observability[k],
                    identified: free.is_some(),
                    held: plan.why_held[k].clone(),
                    prior: slot.param.prior,
                    allowed: slot.param.allowed(),
                    anchored: slot.param.anchor.is_some(),
                }
            })
            .collect();
        // the free effect parameters' places in θ
        let n_theta = pb.effects.n_params();
        let mut place = DMatrix::zeros(n_theta, plan.free_theta.len());
        for (f, &k) in plan.free_theta.iter().enumerate() {
            place[(k, f)] = 1.0;
        }
        Step1Report {
            identified,
            effects,
            cov_p1: &d1 * &cov1 * d1.transpose(),
            cov_p_theta: &d1 * (&post.cov_cross * s2) * place.transpose(),
            cov_theta: &place * (&post.cov_theta * s2) * place.transpose(),
        }
    }
}

/// What step 2 adds: rod 2's parameters and its rows before and after.
pub(super) struct Step2Fit {
    p: Params,
    iterations: usize,
    identified: Vec<Identified>,
    before_rows: Vec<Residual>,
    after_rows: Vec<Residual>,
    /// Covariance of step 2's parameters, and with the 29 of step 1 (see
    /// [`uncertainty::step2_covariance`]).
    cov: DMatrix<f64>,
    cross: DMatrix<f64>,
}

impl Step2Fit {
    /// Step 1's 29 × 29 covariance with step 2's parameters in it: their own block and their
    /// covariance with step 1's (step 2 re-identifies parameters step 1 held).
    fn widen(&self, cov: &mut SMatrix<f64, N_PARAMS, N_PARAMS>) {
        let ids: Vec<usize> = self.identified.iter().map(|id| id.index).collect();
        for (a, &i) in ids.iter().enumerate() {
            for j in 0..N_PARAMS {
                cov[(i, j)] = self.cross[(a, j)];
                cov[(j, i)] = self.cross[(a, j)];
            }
        }
        for (a, &i) in ids.iter().enumerate() {
            for (b, &j) in ids.iter().enumerate() {
                cov[(i, j)] = self.cov[(a, b)];
            }
        }
    }
}

/// Step 2: rod 2 from virtual measurements of the forward instruments (eq. 4.32), made with
/// step 1's parameters; None when the campaign has no forward instrument or nothing to
/// identify there.
pub(super) fn step2<'c>(
    pb: &Problem,
    plan: &Plan,
    fit: &Step1Fit,
    corr: &dyn Fn() -> &'c Corrections,
    cov_p1: &DMatrix<f64>,
    progress: Option<Observer>,
) -> Result<Option<Step2Fit>, CalibrationError> {
    if plan.step2_wanted.is_empty() {
        return Ok(None);
    }
    let corr = corr();
    let opts = pb.opts;
    let p1 = fit.state.p;
    // the virtual q2 rows at p, their virtual measurements made with step 1's p1
    let virtual_rows = |p: &Params| pb.rows(Step::VirtualQ2, p, &p1, corr, &fit.drop);
    let rows2 = virtual_rows(&p1)?;
    let ids2 = match &opts.selection {
        Selection::Auto { max_condition } => auto_select(
            &Columns::of(&rows2, 0),
            &plan.step2_wanted,
            &[],
            *max_condition,
        ),
        Selection::List(_) | Selection::Prior(_) => plan.step2_wanted.clone(),
    };
    if ids2.is_empty() {
        return Ok(None);
    }
    let prior2 = prior_of(&opts.selection, &ids2);
    let jr2 = reduced_jacobian(&rows2, &ids2, &[]);
    let lm = Lm {
        problem: pb,
        step: Step::VirtualQ2,
        p_cal: p1,
        drop: &fit.drop,
        d: dependency(&ids2, &[]),
        h: scaling_vector(&jr2, &ids2, opts.scaling)?,
        // the effects stay in the rows at their identified values
        free_theta: &[],
        h_theta: DVector::zeros(0),
        max_iterations: opts.max_iterations,
        screen: false,
        warm: false,
        prior: prior2.clone(),
        center: pb.start,
        theta_prior: Vec::new(),
        keep: Keep::Nothing,
        initial: None,
        shared: None,
        made: None,
    };
    let res = lm.run(&fit.state, progress)?;
    let p = res.state.p;
    let after_rows = virtual_rows(&p)?;
    let (cov, cross) = step2_covariance(&after_rows, &ids2, &prior2, cov_p1)?;
    let identified = ids2
        .iter()
        .enumerate()
        .map(|(k, &i)| Identified {
            name: NAMES[i],
            index: i,
            nominal: pb.start[i],
            value: p[i],
            sigma: cov[(k, k)].max(0.0).sqrt(),
            step: 2,
        })
        .collect();
    let before_rows = pb.rows(
        Step::VirtualQ2,
        &pb.start,
        &pb.start,
        plan.corr0(pb),
        &fit.drop,
    )?;
    Ok(Some(Step2Fit {
        p,
        iterations: res.iterations,
        identified,
        before_rows,
        after_rows,
        cov,
        cross,
    }))
}
