//! What a running calibration tells its caller, and how the caller stops it: an observer
//! ([`Request::progress`](super::Request::progress)) is called once per Levenberg-Marquardt
//! iteration and once per noise round, and answers [`Flow::Stop`] to end the calibration,
//! which then returns [`CalibrationError::Cancelled`](super::CalibrationError::Cancelled),
//! never a result. The calibrator node's `~/calibrate` action sends its feedback from here
//! and cancels through it; the core knows nothing of either.

use crate::obs::Step;
use crate::variance::NoiseEstimate;

/// Whether the calibration goes on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    Continue,
    /// End the calibration now: it returns `CalibrationError::Cancelled`.
    Stop,
}

/// One event of a running calibration.
#[derive(Clone, Copy, Debug)]
pub enum Progress<'a> {
    /// An LM iteration begins (one call per iteration the fit's `iterations` counts, every
    /// LM run of the calibration: outlier rounds, step 2 and noise rounds alike).
    Iteration {
        /// The rows fitted: the direct ones (step 1) or rod 2's virtual rows (step 2).
        step: Step,
        /// This LM run's iteration, from 1.
        iteration: usize,
        /// The LM's cost at the iteration's start: ½ Σ (r/σ)² of the weighted rows with the
        /// prior's pseudo-rows.
        cost: f64,
    },
    /// A noise round ended ([`super::Noise::Estimate`]): the levels its residuals show, which
    /// weight the next round (the last round's are the calibration's estimate).
    NoiseRound {
        /// From 1.
        round: usize,
        estimate: &'a NoiseEstimate,
    },
}

/// The caller's observer.
pub type Observer<'a> = &'a dyn Fn(&Progress) -> Flow;
