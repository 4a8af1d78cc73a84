//! The held-out figures of one model, made in one place: its TCP errors at the held-out
//! poses, the same with each setup's zero removed (the reading a relative setup was zeroed on
//! is in all its readings, and no model predicts it), each in its own noise, their RMS and
//! the floors noise alone gives. The diagnosis's fits and candidates, its baseline, the
//! held-out judge, `rpkm calibrate`, the calibrator node, the planner's bench and the
//! discovery bench read their held-out figures from here; no other place takes the RMS of
//! held-out errors (tests/layers.rs holds the callers to it). All lengths in mm.

use crate::calib;
use crate::campaign::Campaign;
use crate::obs::{self, PoseError};
use crate::params::{Model, Params};

/// Held-out TCP errors (mm, in [`obs::tcp_errors`] order) and their RMS, as measured and with
/// each setup's zero removed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HeldOutErrors {
    /// Model − measured, each error as read.
    pub values: Vec<f64>,
    /// The same less the mean of their setup and coordinate.
    pub relative: Vec<f64>,
    /// RMS of `values` and of `relative`.
    pub rms: f64,
    pub rms_relative: f64,
}

impl HeldOutErrors {
    /// The errors `values` of readings whose setup and coordinate are `zero` (an index
    /// each: the errors of one share the reading their setup was zeroed on).
    fn of(zero: &[usize], values: Vec<f64>) -> HeldOutErrors {
        let relative = obs::zero_removed(zero, &values);
        HeldOutErrors {
            rms: calib::rms(&values),
            rms_relative: calib::rms(&relative),
            values,
            relative,
        }
    }

    /// The held-out errors of the geometric parameters `p` alone in `model` (no effects, no
    /// noise model): the starting parameters `rpkm calibrate` compares with, a plan's
    /// calibration the bench judges.
    pub fn of_geometry(
        val: &Campaign,
        p: &Params,
        model: Model,
    ) -> Result<HeldOutErrors, PoseError> {
        let errors = obs::tcp_errors(val, p, model)?;
        let values: Vec<f64> = errors.iter().map(|e| e.value).collect();
        Ok(HeldOutErrors::of(&obs::zero_groups(val, &errors), values))
    }
}

/// One calibrated model on the held-out campaign: its errors, the same in their own noise,
/// the parameters it fitted on the held-out setups, and the floors of that noise.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HeldOut {
    pub errors: HeldOutErrors,
    /// The zero-removed errors each divided by its σ: how two models' predictions are
    /// compared. Weighed alike in mm, the tracker's across-beam readings (tens of µm) would
    /// drown what its along-beam ones (a few µm) or the grid encoder's see: a drift of
    /// 1.8 µm/min along the beam moved the RMS from 22.88 to 22.80 µm (± 0.03), from 1.23 to
    /// 1.13 in σ (± 0.04).
    pub scaled: Vec<f64>,
    /// The effects' parameters fitted on the held-out setups themselves (an instrument's
    /// alignment in that mounting).
    pub refit: usize,
    /// RMS that noise alone gives there (mm): counting each setup's zero reading (which all
    /// its readings share, so with few setups the raw RMS strays from it by that one draw),
    /// and with each setup's zero removed.
    pub noise_floor: f64,
    pub noise_floor_relative: f64,
}

/// The noise of the held-out errors a model's figures are read against (the held-out data's,
/// [`super::validation::Validation::noise`]), each error's entry in [`obs::tcp_errors`] order.
pub(crate) struct ErrorNoise<'a> {
    /// Each error's setup and coordinate (an index): the errors of one share the reading
    /// their setup was zeroed on.
    pub zero: &'a [usize],
    /// σ of each error, and of each less the mean of its setup and coordinate.
    pub sigma: &'a [f64],
    pub relative_sigma: &'a [f64],
}

impl HeldOut {
    /// The figures of errors `values` (mm) in the noise `noise`, of a model that fitted
    /// `refit` parameters on the held-out setups.
    pub(crate) fn of(noise: &ErrorNoise, values: Vec<f64>, refit: usize) -> HeldOut {
        let errors = HeldOutErrors::of(noise.zero, values);
        let scaled = errors
            .relative
            .iter()
            .zip(noise.relative_sigma)
            .map(|(e, s)| e / s.max(f64::MIN_POSITIVE))
            .collect();
        HeldOut {
            errors,
            scaled,
            refit,
            noise_floor: calib::rms(noise.sigma),
            noise_floor_relative: calib::rms(noise.relative_sigma),
        }
    }
}
