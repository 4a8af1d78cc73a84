//! A campaign's rows at a calibration's start and at a warm start, evaluated once for several
//! calibrations that differ only in their effects: the diagnosis's candidates, each the
//! current model and one effect more, read their plan and their LM's first normal equations
//! from one evaluation with every candidate's effect columns instead of two each.
//!
//! The rows are the same to the bit: at both points every effect a calibration does not
//! hold is at θ = 0, where it changes no row (its correction adds zero), and each row's
//! derivative by one effect parameter does not depend on the other parameters'. A
//! calibration whose points are not these (another start, θ, noise or drop list) evaluates
//! its own rows.

use super::rows::{in_piece_order, thread_count, Claims, Problem};
use super::types::{CalibrationError, Options, State};
use crate::campaign::Campaign;
use crate::effects::EffectSet;
use crate::noise::NoiseModel;
use crate::obs::{Residual, Step};
use crate::params::{Model, Params, N_PARAMS};
use std::collections::HashSet;

/// The rows of a campaign, piece by piece, at the start (every θ zero) and at a warm start,
/// with the effects of a union: what a calibration [`super::Request`] with `shared` reads a calibration's rows
/// at those points from.
pub struct SharedRows {
    model: Model,
    noise: NoiseModel,
    start: Params,
    warm: Params,
    /// The union's θ at the warm start.
    warm_theta: Vec<f64>,
    /// The union's parameters: effect and parameter name, in θ order.
    slots: Vec<(String, String)>,
    at_start: Vec<Vec<Residual>>,
    at_warm: Vec<Vec<Residual>>,
}

impl SharedRows {
    /// The rows of `campaign` with the effects of `union` (bound to it) at `start` and at
    /// `warm` (parameters and the union's θ), weighted by `opts`' noise.
    pub fn new(
        campaign: &Campaign,
        start: &Params,
        opts: &Options,
        union: &EffectSet,
        (warm, warm_theta): (&Params, &[f64]),
    ) -> Result<SharedRows, CalibrationError> {
        if warm_theta.len() != union.n_params() {
            return Err(CalibrationError::StartThetaLength {
                given: warm_theta.len(),
                expected: union.n_params(),
            });
        }
        let pb = Problem::new(campaign, *start, union, opts);
        let none = HashSet::new();
        let zero = vec![0.0; union.n_params()];
        let at = |p: &Params, theta: &[f64]| {
            let corr = union.corrections(theta, p);
            pb.map_pieces(Step::Direct, p, start, &corr, &none, <[Residual]>::to_vec)
        };
        Ok(SharedRows {
            model: opts.model,
            noise: opts.noise.clone(),
            start: *start,
            warm: *warm,
            warm_theta: warm_theta.to_vec(),
            slots: union
                .layout()
                .into_iter()
                .map(|s| (s.effect, s.param.name))
                .collect(),
            at_start: at(start, &zero)?,
            at_warm: at(warm, warm_theta)?,
        })
    }

    /// The rows of the calibration `pb` at its start (θ₀) and at the LM's start `init`, if
    /// they are these: the same options' model and noise, the same points, each of its
    /// effect parameters one of the union's and every other union parameter zero.
    pub(super) fn view(&self, pb: &Problem, theta0: &[f64], init: &State) -> Option<View<'_>> {
        let same = pb.opts.model == self.model
            && pb.opts.noise == self.noise
            && same_params(&pb.start, &self.start)
            && same_params(&init.p, &self.warm)
            && self.at_start.len() == pb.pieces.len();
        if !same {
            return None;
        }
        let theta_of: Vec<usize> = pb
            .effects
            .layout()
            .iter()
            .map(|s| {
                self.slots
                    .iter()
                    .position(|(e, n)| *e == s.effect && *n == s.param.name)
            })
            .collect::<Option<_>>()?;
        let mut warm = vec![0.0; self.slots.len()];
        for (&u, &v) in theta_of.iter().zip(&init.theta) {
            warm[u] = v;
        }
        let zero_at_start = theta0.iter().all(|v| v.to_bits() == 0);
        let at_warm = warm
            .iter()
            .zip(&self.warm_theta)
            .all(|(a, b)| a.to_bits() == b.to_bits());
        (zero_at_start && at_warm && theta_of.len() == init.theta.len()).then(|| View {
            at_start: &self.at_start,
            at_warm: &self.at_warm,
            theta_of,
            threads: thread_count(pb.opts.threads),
        })
    }
}

/// Whether two parameter sets are the same to the bit.
fn same_params(a: &Params, b: &Params) -> bool {
    (0..N_PARAMS).all(|i| a[i].to_bits() == b[i].to_bits())
}

/// One calibration's view of [`SharedRows`]: its effect parameters' places among the
/// union's.
pub(super) struct View<'a> {
    pub at_start: &'a [Vec<Residual>],
    pub at_warm: &'a [Vec<Residual>],
    theta_of: Vec<usize>,
    threads: usize,
}

impl View<'_> {
    /// `each` applied to every piece of `pieces` (one of the view's) as the calibration's own
    /// rows (its effect columns only), on the calibration's threads; the results in piece
    /// order, as [`Problem::map_pieces`] gives them.
    pub fn map<T: Send>(
        &self,
        pieces: &[Vec<Residual>],
        each: impl Fn(&[Residual]) -> T + Sync,
    ) -> Vec<T> {
        let n = pieces.len();
        // the pieces this worker claims, one after the other; the row buffer reused
        let run = |claims: Claims| {
            let mut rows = Vec::new();
            let mut out = Vec::new();
            for k in claims {
                rows.clear();
                rows.extend(pieces[k].iter().map(|r| self.own(r)));
                out.push((k, each(&rows)));
            }
            out
        };
        in_piece_order(self.threads.min(n.max(1)), n, run)
    }

    /// A union row as the calibration's own: its effect columns picked out.
    fn own(&self, r: &Residual) -> Residual {
        Residual {
            pose: r.pose,
            instrument: r.instrument,
            direction: r.direction,
            value: r.value,
            sigma: r.sigma,
            parts: r.parts,
            jacobian: r.jacobian,
            d_pcal: r.d_pcal.clone(),
            d_theta: self.theta_of.iter().map(|&u| r.d_theta[u]).collect(),
            reset_gain: r.reset_gain,
        }
    }
}
