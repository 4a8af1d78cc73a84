//! The held-out data with their noise: each held-out TCP error's σ, raw and with its setup's
//! zero removed (the reading a relative setup was zeroed on is in all its readings, and no
//! model predicts it), by noise group, and which errors share a zero. What the held-out judge
//! ([`crate::diagnose::held_out`]) weighs a model's errors by.

use super::figures::ErrorNoise;
use crate::campaign::{Campaign, Instrument};
use crate::diagnose::types::DiagnoseError;
use crate::geometry;
use crate::noise::{self, NoiseModel, Parts, XyInstrument, N_GROUPS};
use crate::obs::{self, PoseError};
use crate::params::{Model, Params};
use nalgebra::Vector2;

/// Held-out data with their noise.
pub(crate) struct Validation<'a> {
    pub campaign: &'a Campaign,
    /// σ of each held-out TCP error, in [`obs::tcp_errors`] order.
    pub sigma: Vec<f64>,
    /// σ of each error less the mean of its setup and coordinate ([`Validation::relative`]):
    /// the zero reading cancels, the mean's own noise does not.
    pub relative_sigma: Vec<f64>,
    /// The variance of each relative error by noise group (what the floor's degrees of
    /// freedom come from).
    pub(in crate::diagnose) relative_parts: Vec<Parts>,
    /// Each error's setup and coordinate (an index): the errors of one share the reading
    /// their setup was zeroed on.
    pub(in crate::diagnose) zero: Vec<usize>,
    /// Each error's pose and coordinate, in order.
    pub(in crate::diagnose) at: Vec<(usize, &'static str)>,
}

impl Validation<'_> {
    /// The held-out campaign with the noise of each of its TCP errors.
    pub fn new<'a>(
        campaign: &'a Campaign,
        noise: &NoiseModel,
    ) -> Result<Validation<'a>, PoseError> {
        let errs = obs::tcp_errors(campaign, &Params::nominal(), Model::M29)?;
        let variances = validation_variances(campaign, &errs, noise)?;
        let zero = obs::zero_groups(campaign, &errs);
        // var(e_i − ē) = σ_i² (1 − 2/n) + Σ σ_j² / n² over the n errors of the group, for
        // each noise group's part alike
        let count = obs::group_sums(&zero, &vec![1.0; zero.len()]);
        let mut group_parts = vec![[0.0; N_GROUPS]; count.len()];
        for (&g, v) in zero.iter().zip(&variances) {
            for (sum, part) in group_parts[g].iter_mut().zip(&v.reading) {
                *sum += part;
            }
        }
        let relative_parts: Vec<Parts> = zero
            .iter()
            .zip(&variances)
            .map(|(&g, v)| {
                let n = count[g].1.max(1) as f64;
                std::array::from_fn(|k| {
                    obs::zero_removed_variance(v.reading[k], group_parts[g][k], n)
                })
            })
            .collect();
        Ok(Validation {
            campaign,
            sigma: variances
                .iter()
                .map(|v| (v.reading.iter().sum::<f64>() + v.zero).sqrt())
                .collect(),
            relative_sigma: relative_parts
                .iter()
                .map(|p| p.iter().sum::<f64>().sqrt())
                .collect(),
            relative_parts,
            zero,
            at: errs
                .iter()
                .map(|e| (e.pose, e.direction.as_str()))
                .collect(),
        })
    }

    /// `errors` less the mean of their setup and coordinate: what a model can predict of
    /// them (no model predicts the error of the reading a setup was zeroed on, and one that
    /// happens to follow it would beat the truth).
    pub fn relative(&self, errors: &[f64]) -> Vec<f64> {
        obs::zero_removed(&self.zero, errors)
    }

    /// The noise a model's held-out figures are read against.
    pub(in crate::diagnose) fn noise(&self) -> ErrorNoise<'_> {
        ErrorNoise {
            zero: &self.zero,
            sigma: &self.sigma,
            relative_sigma: &self.relative_sigma,
        }
    }

    /// The number of (setup, coordinate) groups: the degrees of freedom the zero removal
    /// takes.
    pub(in crate::diagnose) fn n_groups(&self) -> usize {
        self.zero.iter().max().map_or(0, |m| m + 1)
    }
}

/// The held-out campaign with the noise of each of its TCP errors.
pub(crate) fn held_out<'a>(
    validation: Option<&'a Campaign>,
    noise: &NoiseModel,
) -> Result<Option<Validation<'a>>, DiagnoseError> {
    validation
        .map(|v| Validation::new(v, noise))
        .transpose()
        .map_err(DiagnoseError::Validation)
}

/// The variance of one held-out TCP error by noise group: its own reading's (and its
/// encoders'), and the reading its setup was zeroed on (every error of the setup shares that
/// one draw).
struct ErrorVariance {
    reading: Parts,
    zero: f64,
}

/// The variance of every held-out TCP error, in [`obs::tcp_errors`] order: the instrument's
/// noise at the pose and at its setup's reset pose (zeroed on a reading as noisy as any
/// other), and the encoders' at both.
fn validation_variances(
    val: &Campaign,
    errs: &[obs::TcpError],
    noise: &NoiseModel,
) -> Result<Vec<ErrorVariance>, PoseError> {
    let nominal = Params::nominal();
    let mut reset_of = vec![None; val.poses.len()];
    for setup in val.setups() {
        for &i in &setup.poses {
            reset_of[i] = setup.reset;
        }
    }
    let parts = |i: usize, direction: obs::TcpDirection| -> Result<Parts, PoseError> {
        let pose = &val.poses[i];
        let tcp = geometry::fgm(&nominal, Model::M29, pose.q[0], pose.q[3])
            .map_err(|e| PoseError::at(val, pose, e))?;
        let at = Vector2::new(tcp.x(), tcp.y());
        let reading = match (direction, XyInstrument::of(pose.instrument)) {
            (obs::TcpDirection::X, Some(xy)) => noise.xy_parts(xy, at, Vector2::new(1.0, 0.0)),
            (obs::TcpDirection::Y, Some(xy)) => noise.xy_parts(xy, at, Vector2::new(0.0, 1.0)),
            _ => noise.scalar_parts(pose.instrument, 1.0),
        };
        Ok(noise::add(reading, noise.encoder_parts(1.0)))
    };
    errs.iter()
        .map(
            |&obs::TcpError {
                 pose: i, direction, ..
             }| {
                // the reading the setup was zeroed on is in every error of the setup (none for a
                // ball-bar, zeroed on no reading; the reset's encoders for every instrument)
                let zero = match reset_of[i] {
                    Some(r) if val.poses[r].instrument == Instrument::Dbb => {
                        noise.encoder_mm.powi(2)
                    }
                    Some(r) => parts(r, direction)?.iter().sum(),
                    None => 0.0,
                };
                Ok(ErrorVariance {
                    reading: parts(i, direction)?,
                    zero,
                })
            },
        )
        .collect()
}
