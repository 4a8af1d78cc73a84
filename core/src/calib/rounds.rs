//! The one way into a calibration: [`calibrate`] answers a [`Request`] with the calibration
//! and the noise its rows were weighted by, making the noise rounds where the request asks
//! for them. The diagnosis makes its calls here, the commands and the calibrator node theirs
//! through [`super::calibrate_command`], so a change of how rows are weighted is made here
//! once.

use super::fit::fit_once;
use super::progress::{Flow, Progress};
use super::request::{Noise, Request};
use super::types::{Calibration, CalibrationError, WarmStart};
use crate::effects::EffectSet;
use crate::variance::{GroupLevels, NoiseEstimate};

/// Calibrate as `req` asks. With [`Noise::Stated`] the estimate is the stated model as it is.
pub fn calibrate(req: &Request) -> Result<(Calibration, NoiseEstimate), CalibrationError> {
    match req.noise {
        Noise::Stated => fit_once(req).map(|c| (c, NoiseEstimate::assumed(&req.options.noise))),
        Noise::Estimate { rounds } => estimating(req, rounds.max(1)),
    }
}

/// The noise rounds: each starts where the last ended (only the weights changed, so the LM
/// takes one or two steps instead of a calibration's four or five from the start).
fn estimating(
    req: &Request,
    max_rounds: usize,
) -> Result<(Calibration, NoiseEstimate), CalibrationError> {
    let stated = &req.options.noise;
    let mut opts = req.options.clone();
    let mut levels = GroupLevels::default();
    let mut rounds = 0;
    let mut last: Option<Calibration> = None;
    // the effects bound at the last round's parameters (`EffectSet::rebound`)
    let mut bound_at_fit: Option<EffectSet> = None;
    let mut rebinds = req.effects.rebinds();
    let cal = loop {
        let effects = bound_at_fit.as_ref().unwrap_or(req.effects);
        let warm = last.as_ref().map(|c| WarmStart {
            params: &c.params,
            theta: &c.theta,
            screen: false,
        });
        let cal = match (rounds, req.first_round) {
            (0, Some(first)) => first.clone(),
            _ => fit_once(&Request {
                options: &opts,
                effects,
                warm: warm.or(req.warm),
                ..*req
            })?,
        };
        rounds += 1;
        let step = levels.step(&cal.residuals, &cal.leverage);
        // a fit whose effects were bound at the start has a model error the next round,
        // bound at this fit, removes: settled weights alone do not end the rounds
        let bound_here = !rebinds || bound_at_fit.is_some();
        if (GroupLevels::settled(&step) && bound_here) || rounds >= max_rounds {
            break cal;
        }
        if rebinds {
            // an effect that bound at the start and not at the fit (a pose the fit moved to
            // a singular configuration) keeps its binding at the start
            bound_at_fit = req
                .effects
                .rebound(req.campaign, &cal.params, &cal.theta)
                .and_then(Result::ok);
            rebinds = bound_at_fit.is_some();
        }
        opts.noise = levels.apply(&step, stated);
        opts.noise_inflation = req.options.noise_inflation * levels.inflation();
        round_ended(req, || {
            levels.estimate(
                req.campaign,
                stated,
                opts.noise.clone(),
                &cal.residuals,
                rounds,
            )
        })?;
        last = Some(cal);
    };
    let estimate = levels.estimate(req.campaign, stated, opts.noise, &cal.residuals, rounds);
    round_ended(req, || estimate.clone())?;
    Ok((cal, estimate))
}

/// Tells `req`'s observer, if any, that a noise round ended with the estimate `shown` makes
/// (made only when someone listens).
fn round_ended(
    req: &Request,
    shown: impl FnOnce() -> NoiseEstimate,
) -> Result<(), CalibrationError> {
    let Some(observer) = req.progress else {
        return Ok(());
    };
    let estimate = shown();
    match observer(&Progress::NoiseRound {
        round: estimate.rounds,
        estimate: &estimate,
    }) {
        Flow::Continue => Ok(()),
        Flow::Stop => Err(CalibrationError::Cancelled),
    }
}
