//! Geometric calibration (thesis chapter 3, 4.2-4.3): Levenberg-Marquardt on the weighted
//! model-minus-measurement rows of `obs`, with parameter scaling, the dependency matrix D,
//! outlier elimination per measurement direction, parameter uncertainties, and the two-step
//! procedure of the forward instruments.

mod command;
mod fit;
mod lags;
mod lm;
mod plan;
mod progress;
mod report;
mod request;
mod rounds;
mod rows;
mod select;
mod shared;
pub mod tie;
mod types;
mod uncertainty;

pub use command::{calibrate_command, CommandCalibration, CommandError, CommandRequest};
pub use lags::{time_constants, TimeConstant};
pub use progress::{Flow, Observer, Progress};
pub use report::{gain, rms};
pub use request::{Noise, Request};
pub use rounds::calibrate;
pub use select::{MIN_EFFECT_OBSERVABILITY, MIN_EFFECT_SIGNAL};
pub use shared::SharedRows;
pub use types::{
    anchored_terms, AnchoredTerms, Calibration, CalibrationError, DirectionRms, EffectEstimate,
    Identified, Link, Options, Outlier, Prior, Scaling, Selection, Stop, WarmStart,
};
