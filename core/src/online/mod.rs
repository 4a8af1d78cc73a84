//! Calibration that never stops (issue 15): the 29 parameters and the stiffness factor
//! tracked from the drive forces of a machine at work, all four drives position-controlled.
//!
//! A module beside [`crate::calib`], one layer above it: it starts from a calibration's
//! estimate and covariance and settles its ties with `calib::tie`; `calib` never names it.
//!
//! An extended Kalman filter over the state (p, dk), dk the relative change of the default
//! stiffness, fed by decimated drive samples (q, f1..f4):
//!
//! - predict: the parameters are random walks (lengths and angles drift with temperature and
//!   wear at [`OnlineOptions::length_drift_mm_per_sqrt_h`] ...), the covariance grows with the
//!   time since the last sample;
//! - update: the four force rows of the sample (`obs::force_jacobian`: the elastic model's
//!   forces at the estimate, their Jacobian, the stiffness column f / (1 + dk)) weighted by
//!   the forces' covariance with the encoders' share, the calibration's noise model
//!   ([`DriveNoise`]: an encoder's 0.2 µm is 10-20 N of force), in information form,
//!   static-size matrices, nothing allocated per sample;
//! - step changes: a sample whose normalised innovation exceeds the gate (χ²₄ at 1e-6) is
//!   held back; [`OnlineOptions::step_samples`] in a row are a step (one lone sample is an
//!   outlier, dropped): the single parameter that best explains the held samples' innovations
//!   is named, its variance opened by the step's square, and the held samples are applied;
//! - ties: a step the path moved alike for two parameters ("l3 or l1") keeps a second
//!   estimate with the runner-up's change until the two estimates' predictions of the
//!   samples since tell them apart ([`crate::calib::tie`]); [`OnlineEstimator::tie_motion`] plans
//!   the poses that would.
//!
//! The forces determine some combinations of the parameters (`rpkm analyze observability
//! --method currents`); the start covariance (a calibration's, or the tolerances) holds the
//! rest, whose σ then grows with the drift allowed.
//!
//! Drift: the random walk that lets the estimate follow a drift widens its σ by as much, so
//! [`DriftMonitor`] weighs the estimate's change since a reference in the covariance that
//! change would have had were nothing to have moved ([`OnlineEstimator::change`]), the
//! expansion of rods and frame fitted out, and tests whether a candidate's creep (a rod's,
//! by default) explains it beyond noise: 1 dof per candidate, not the χ² of the whole change,
//! which under noise alone grows without bound over hours (see [`DriftTest`]).
//!
//! Files, one job each:
//! - `options.rs`: The state's layout, the options of the filter, the step test and the tie
//!   test, and their defaults.
//! - `estimator.rs`: The estimator's state and results: construction from a calibration, the
//!   random-walk prediction, the readings of the estimate.
//! - `filter.rs`: One sample in: the forces linearised at the estimate, gated, applied in
//!   information form.
//! - `step.rs`: Step changes: the held samples' innovations attributed to the one parameter
//!   that best explains them.
//! - `ties.rs`: Ties: a step explained alike by two parameters, the two estimates'
//!   predictions until the evidence parts them, and the motion that would.
//! - `change.rs`: The estimate's change since a reference and its covariance had nothing
//!   moved, with the filter's response to a creep.
//! - `force_noise.rs`: The force noise the innovations show, from the differences of
//!   successive innovations.
//! - `drift.rs`: The drift test: whether a candidate's creep explains the change beyond
//!   noise, and the creep named.
//! - `monitor.rs`: The drift monitor: the estimate's history, its settling times and the
//!   drift test run on it.
//! - `tests.rs`: the module's unit tests.

mod change;
mod drift;
mod estimator;
mod filter;
mod force_noise;
mod monitor;
mod options;
mod step;
#[cfg(test)]
mod tests;
mod ties;

pub use change::{DriftInput, EstimateChange};
pub use drift::{
    Drift, DriftTest, DRIFT_FALSE_ALARM, DRIFT_NAME_MARGIN, DRIFT_SETTLE_AFTER_STEP_S,
    DRIFT_SETTLE_S, FOLLOWS,
};
pub use estimator::{
    DetectedStep, ForceSample, OnlineEstimator, TieResolved, TieSoFar, UpdateOutcome,
};
pub use monitor::DriftMonitor;
pub use options::{
    Covariance, OnlineOptions, StepCandidates, GATE_CHI2_4, N_STATE, STIFFNESS, TIE_EVIDENCE_CHI2,
    TIE_MOTION_POSES,
};
