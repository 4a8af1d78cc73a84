//! The one way into a calibration: a [`Request`] says what to calibrate, from where, and how
//! its rows are weighted; [`calibrate`] answers with the calibration and the noise its rows
//! were weighted by. `rpkm calibrate`, the diagnosis and the calibrator node each make one
//! call, so a change of how rows are weighted is made here once.

use super::progress::round_ended;
use super::{fit_once, Calibration, CalibrationError, Options, SharedRows, WarmStart};
use crate::campaign::Campaign;
use crate::effects::EffectSet;
use crate::params::Params;
use crate::variance::{Levels, NoiseEstimate, MAX_ROUNDS};

/// How the rows are weighted. The stated levels are [`Options::noise`] in both cases.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Noise {
    /// By the stated levels as they are.
    Stated,
    /// By each noise group's level as the campaign's own residuals show it (variance
    /// components, [`crate::variance`]): fit with the stated levels, estimate each group's,
    /// re-weight, re-fit, until the levels settle or `rounds` fits were made.
    Estimate { rounds: usize },
}

impl Noise {
    /// Estimated, with the rounds every command uses.
    pub const ESTIMATE: Noise = Noise::Estimate { rounds: MAX_ROUNDS };
}

/// What to calibrate and how. [`Request::new`] gives a calibration of the campaign without
/// effects, weighted by the stated noise; the other fields are set by name.
#[derive(Clone, Copy)]
pub struct Request<'a> {
    pub campaign: &'a Campaign,
    /// The parameters the prior is centred on and the "before" of the report.
    pub start: &'a Params,
    pub options: &'a Options,
    /// Physical effects in the model, bound to `campaign`.
    pub effects: &'a EffectSet,
    /// The effects' parameters at the start (empty: all zero).
    pub theta0: &'a [f64],
    pub noise: Noise,
    /// Where the LM starts when not at `start` (the first round's start when estimating).
    pub warm: Option<WarmStart<'a>>,
    /// Rows at the start and the warm start evaluated once for several calibrations.
    pub shared: Option<&'a SharedRows>,
    /// The first round when estimating the noise, already made by the caller: this request
    /// with [`Noise::Stated`]. A caller that has it (the diagnosis's first round) does not
    /// pay for it twice; it is not checked to be that calibration.
    pub first_round: Option<&'a Calibration>,
    /// Told of each LM iteration and noise round; it may stop the calibration (`progress`).
    pub progress: Option<super::Observer<'a>>,
}

impl<'a> Request<'a> {
    pub fn new(campaign: &'a Campaign, start: &'a Params, options: &'a Options) -> Self {
        Request {
            campaign,
            start,
            options,
            effects: EffectSet::none(),
            theta0: &[],
            noise: Noise::Stated,
            warm: None,
            shared: None,
            first_round: None,
            progress: None,
        }
    }
}

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
    let mut levels = Levels::default();
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
        if (Levels::settled(&step) && bound_here) || rounds >= max_rounds {
            break cal;
        }
        if rebinds {
            // an effect that bound at the start and not at the fit (a pose the fit moved to
            // a singular configuration) keeps its binding at the start
            bound_at_fit = req
                .effects
                .rebound(req.campaign, &cal.params)
                .and_then(Result::ok);
            rebinds = bound_at_fit.is_some();
        }
        opts.noise = levels.apply(&step, stated);
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
