//! The calibration every command shares: `rpkm calibrate`, `rpkm plan`, `rpkm bench plan`
//! and the calibrator node each ask [`calibrate_command`] for it, so that binding the
//! effects to the campaign and weighting the rows is written once. Each keeps its own
//! [`Options`] (what its arguments or parameters say); the diagnosis, whose fits share rows
//! and warm starts, asks [`super::calibrate`] directly.

use super::progress::Observer;
use super::request::{Noise, Request};
use super::rounds::calibrate;
use super::types::{Calibration, CalibrationError, Options};
use crate::campaign::Campaign;
use crate::effects::{Effect, EffectSet, NotApplicable};
use crate::params::Params;
use crate::variance::NoiseEstimate;

/// What a command asks of its calibration.
#[derive(Clone, Copy)]
pub struct CommandRequest<'a> {
    pub campaign: &'a Campaign,
    /// The parameters the effects are bound at, the prior is centred on and the LM starts
    /// from (the nominal set unless the command is given one).
    pub start: &'a Params,
    pub options: &'a Options,
    /// The effects in the model, in order, each parameter from its own start
    /// ([`crate::effects::EffectParam::start`]).
    pub effects: &'a [&'a dyn Effect],
    /// How the rows are weighted.
    pub noise: Noise,
    /// Told of each LM iteration and noise round; it may stop the calibration.
    pub progress: Option<Observer<'a>>,
}

impl<'a> CommandRequest<'a> {
    /// `campaign` calibrated from `start` with `effects`, the noise estimated from the
    /// campaign (what every command does unless told to weight by the stated noise).
    pub fn new(
        campaign: &'a Campaign,
        start: &'a Params,
        options: &'a Options,
        effects: &'a [&'a dyn Effect],
    ) -> Self {
        CommandRequest {
            campaign,
            start,
            options,
            effects,
            noise: Noise::ESTIMATE,
            progress: None,
        }
    }
}

/// A command's calibration with what the command reads after it.
#[derive(Debug)]
pub struct CommandCalibration {
    /// The effects as bound to the campaign at the start (their corrections, their layout).
    pub effects: EffectSet,
    pub calibration: Calibration,
    /// The noise the rows were weighted by, stated and estimated.
    pub noise: NoiseEstimate,
}

/// Why a command's calibration failed: each says so in its own words (the argument or
/// parameter that named the effects).
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// An effect cannot be bound to the campaign.
    #[error(transparent)]
    Effects(NotApplicable),
    #[error(transparent)]
    Calibration(CalibrationError),
}

/// The effects bound to the campaign at the start, then the calibration as `req` asks.
pub fn calibrate_command(req: &CommandRequest) -> Result<CommandCalibration, CommandError> {
    let effects =
        EffectSet::bind(req.effects, req.campaign, req.start).map_err(CommandError::Effects)?;
    let (calibration, noise) = calibrate(&Request {
        effects: &effects,
        noise: req.noise,
        progress: req.progress,
        ..Request::new(req.campaign, req.start, req.options)
    })
    .map_err(CommandError::Calibration)?;
    Ok(CommandCalibration {
        effects,
        calibration,
        noise,
    })
}
