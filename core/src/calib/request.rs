//! What a calibration is asked for: a [`Request`] says what to calibrate, from where, and how
//! its rows are weighted ([`Noise`]); [`super::calibrate`] answers it.

use super::progress::Observer;
use super::shared::SharedRows;
use super::types::{Calibration, Options, WarmStart};
use crate::campaign::Campaign;
use crate::effects::EffectSet;
use crate::params::Params;
use crate::variance::MAX_ROUNDS;

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
    pub progress: Option<Observer<'a>>,
    /// Whether the rows' leverages are made ([`Calibration::leverage`], which the noise
    /// rounds read: [`Noise::Estimate`] makes them whatever this says). A campaign above
    /// `KEEP_JACOBIAN_POSES` poses makes them in a pass of its own over the rows, a fifth
    /// of a screened candidate's time: the diagnosis's candidates, which never read them,
    /// ask for none, and their `leverage` is empty.
    pub leverages: bool,
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
            leverages: true,
        }
    }
}
