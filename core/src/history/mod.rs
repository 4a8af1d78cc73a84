//! A machine's history, the arithmetic: what changed between two calibrations and whether it
//! is real ([`change`]), and how each parameter moves over many ([`trend`]: a weighted line
//! with its significance, and when it leaves its tolerance). Pure: the calibrations come in
//! as [`Estimate`]s; where they are kept is the `rpkm-history` crate's business.
//!
//! A calibration under the tolerance prior (`calib::Selection::Prior`) reports every
//! parameter, but only those the campaign *determined* carry its information; the others sit
//! at the prior with the prior's σ. A parameter is determined by a calibration when its
//! posterior variance is below half the prior's: the data's information on it exceeds the
//! prior's, the one-parameter form of the count `Calibration::determined` makes over the
//! eigen-directions. A change or a trend is stated only over what both (or all) calibrations
//! determined; a change nobody could see is unknown, not zero.

mod change;
mod estimate;
mod trend;

pub use change::{
    change, Change, ChangeVerdict, Joint, LargestChange, ParamChange, Seen, CHANGE_P_VALUE,
    FLAG_SIGMA,
};
pub use estimate::Estimate;
pub use trend::{crossing, trend, Crossing, Trend, TrendPoint, LINE_P_VALUE, MIN_POINTS};
