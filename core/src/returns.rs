//! Drift checks: a relative setup that ends where it was zeroed. A tracker, grid encoder or
//! interferometer is zeroed on a reading at its setup's reset pose; a later pose at the same
//! drive positions (a *return*) should read the model's move from there, about zero. What it
//! reads beyond that, against the noise of the return's reading and of the zero's, is how far
//! the instrument drifted since its zero: an instrument that creeps looks like geometry to a
//! calibration that cannot see it this way.
//!
//! Each return is judged on its own: its residual per coordinate (reading less the model's
//! move, µm-ready in mm) with its σ from the noise model, the time since the zero, a rate, and
//! a χ² of the residual against its covariance (both readings' noise and the encoders') with
//! its p-value. The figures are here; the sentence ("lt setup 3 moved 9 µm during 450 s") is
//! the caller's.

use crate::campaign::{Campaign, Instrument, MeasuredPose};
use crate::effects::Corrections;
use crate::geometry::{self, GeometryError};
use crate::noise::{NoiseModel, XyInstrument};
use crate::obs::{self, PoseError};
use crate::params::{Model, Params};
use crate::stats;
use nalgebra::{Matrix2, Vector2};

/// A pose returns to its setup's reset pose where its q1 and q4 (the drives that set the
/// TCP in the model) are within this of the reset's, mm: the same command, read by encoders
/// good to a fraction of a micrometre.
pub const RETURN_TOLERANCE_MM: f64 = 0.005;

/// A return is called a drift where its χ² is this unlikely under the noise alone.
pub const DRIFT_P_VALUE: f64 = 0.01;

/// One coordinate of a return's residual.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DriftComponent {
    /// `x`, `y` or `r`.
    pub coordinate: obs::TcpDirection,
    /// The reading less the model's move from the zero, mm: how far the instrument drifted.
    pub value_mm: f64,
    /// Its σ from the noise model (the return's reading, the zero's, the encoders'), mm.
    pub sigma_mm: f64,
}

/// A setup's return reading judged against its noise.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ReturnDrift {
    pub setup: String,
    pub instrument: Instrument,
    /// Line of the return reading in its file.
    pub line: usize,
    /// Seconds between the zero (the reset pose) and the return.
    pub seconds: f64,
    pub components: Vec<DriftComponent>,
    /// The residual's length, mm, and its rate, mm/s (its length over `seconds`).
    pub magnitude_mm: f64,
    pub rate_mm_per_s: f64,
    /// χ² of the residual against its covariance, its degrees of freedom, and the
    /// probability of one as large from the noise alone.
    pub chi2: f64,
    pub dof: usize,
    pub p_value: f64,
}

impl ReturnDrift {
    /// Whether the return differs from zero by more than its noise ([`DRIFT_P_VALUE`]).
    pub fn moved(&self) -> bool {
        self.p_value < DRIFT_P_VALUE
    }
}

/// Every return reading of `campaign` (a non-reset pose of a relative setup after its reset
/// pose, at its drive positions within [`RETURN_TOLERANCE_MM`]), judged with the calibrated
/// parameters `p` of `model`, the effects' corrections `corr` at their calibrated values, and
/// the noise `noise`. Empty where no setup returns.
pub fn drift_checks(
    campaign: &Campaign,
    (p, model): (&Params, Model),
    corr: &Corrections,
    noise: &NoiseModel,
) -> Result<Vec<ReturnDrift>, PoseError> {
    let returns = return_poses(campaign);
    if returns.is_empty() {
        return Ok(Vec::new());
    }
    let errors = obs::tcp_errors_with(campaign, p, model, corr)?;
    let mut out = Vec::with_capacity(returns.len());
    for (reset, i) in returns {
        let (pose, zero) = (&campaign.poses[i], &campaign.poses[reset]);
        let mine: Vec<&obs::TcpError> = errors.iter().filter(|e| e.pose == i).collect();
        if mine.is_empty() {
            continue;
        }
        let at = |pose: &MeasuredPose| {
            reading_covariance(pose, (p, model), noise)
                .map_err(|e| PoseError::at(campaign, pose, e))
        };
        // a ball-bar is zeroed on no reading (its pivot is where the machine stood)
        let zeroed = if zero.instrument == Instrument::Dbb {
            Matrix2::identity() * noise.encoder_mm.powi(2)
        } else {
            at(zero)?
        };
        let cov = at(pose)? + zeroed;
        out.push(judge(pose, zero, &mine, &cov));
    }
    Ok(out)
}

/// (reset pose, return pose) of every return in `campaign`, in file order.
fn return_poses(campaign: &Campaign) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for setup in campaign.setups() {
        let Some(reset) = setup.reset else { continue };
        let r = &campaign.poses[reset];
        if !r.instrument.is_relative() {
            continue;
        }
        for &i in setup.poses.iter().filter(|&&i| i > reset) {
            let pose = &campaign.poses[i];
            let near = [0, 3]
                .iter()
                .all(|&k| (pose.q[k] - r.q[k]).abs() <= RETURN_TOLERANCE_MM);
            if !pose.reset && near {
                out.push((reset, i));
            }
        }
    }
    out
}

/// The covariance of one reading's (x, y) error at `pose` (a single coordinate in x), its
/// encoders' included.
fn reading_covariance(
    pose: &MeasuredPose,
    (p, model): (&Params, Model),
    noise: &NoiseModel,
) -> Result<Matrix2<f64>, GeometryError> {
    let encoder = Matrix2::identity() * noise.encoder_mm.powi(2);
    if let Some(xy) = XyInstrument::of(pose.instrument) {
        let sol = geometry::fgm(p, model, pose.q[0], pose.q[3])?;
        return Ok(noise.xy_covariance(xy, Vector2::new(sol.x(), sol.y())) + encoder);
    }
    let s = noise.scalar_sigma(pose.instrument).unwrap_or(0.0);
    Ok(Matrix2::new(s * s, 0.0, 0.0, 0.0) + encoder)
}

/// The return at `pose` of the setup zeroed at `zero`, its TCP errors `errors` (model less
/// reading), against the covariance `cov` of the difference of the two readings.
fn judge(
    pose: &MeasuredPose,
    zero: &MeasuredPose,
    errors: &[&obs::TcpError],
    cov: &Matrix2<f64>,
) -> ReturnDrift {
    let seconds = pose.t - zero.t;
    // the drift is the reading beyond the model's move: minus the error
    let values: Vec<f64> = errors.iter().map(|e| -e.value).collect();
    let components: Vec<DriftComponent> = errors
        .iter()
        .zip(&values)
        .map(|(e, &v)| {
            // a single coordinate's variance is the first (reading_covariance)
            let k = usize::from(e.direction == obs::TcpDirection::Y && values.len() == 2);
            DriftComponent {
                coordinate: e.direction,
                value_mm: v,
                sigma_mm: cov[(k, k)].sqrt(),
            }
        })
        .collect();
    let chi2 = if let [x, y] = values[..] {
        cov.try_inverse().map_or(f64::INFINITY, |inv| {
            (Vector2::new(x, y).transpose() * inv * Vector2::new(x, y))[0]
        })
    } else {
        components
            .iter()
            .map(|c| (c.value_mm / c.sigma_mm).powi(2))
            .sum()
    };
    let magnitude_mm = values.iter().map(|v| v * v).sum::<f64>().sqrt();
    ReturnDrift {
        setup: pose.setup.clone(),
        instrument: pose.instrument,
        line: pose.line,
        seconds,
        magnitude_mm,
        rate_mm_per_s: if seconds > 0.0 {
            magnitude_mm / seconds
        } else {
            0.0
        },
        chi2,
        dof: values.len(),
        p_value: stats::chi2_upper_tail(chi2, values.len() as f64),
        components,
    }
}
