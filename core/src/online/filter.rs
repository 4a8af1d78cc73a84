//! One sample in: the forces linearised at the estimate, gated, applied in information form.

use super::estimator::{ForceSample, Held, OnlineEstimator, UpdateOutcome};
use super::force_noise::ForceNoise;
use super::options::{scale, Covariance, Rows, GATE_CHI2_4, N_STATE, STIFFNESS};
use crate::calib::tie::Verdict;
use crate::elastic::ElasticError;
use crate::obs::{force_jacobian, force_position_gains};
use crate::params::N_PARAMS;
use nalgebra::{Matrix4, SVector, Vector4};

impl OnlineEstimator {
    /// The sample's force rows at the estimate: Jacobian over the state and innovation.
    pub(super) fn linearise(&mut self, s: &ForceSample) -> Result<Held, ElasticError> {
        let k = self.stiffness();
        let (eq, dp) = match force_jacobian(&self.p, &k, s.q, self.warm.as_ref()) {
            Ok(v) => v,
            // a warm start from a far pose (a jump in the stream): solve cold
            Err(_) if self.warm.is_some() => force_jacobian(&self.p, &k, s.q, None)?,
            Err(e) => return Err(e),
        };
        let gains = force_position_gains(&self.p, &k, s.q, &eq)?;
        let noise = self.opts.drives().modes(&gains);
        self.warm = Some(eq);
        let mut h = Rows::zeros();
        let mut y = Vector4::zeros();
        let d = scale();
        for a in 0..4 {
            for j in 0..N_PARAMS {
                h[(a, j)] = dp[a][j] * d[j];
            }
            h[(a, STIFFNESS)] = eq.drive_force[a] / (1.0 + self.dk) * d[STIFFNESS];
            y[a] = s.f[a] - eq.drive_force[a];
        }
        Ok(Held {
            sample: *s,
            h,
            y,
            r: noise.covariance(),
            info: noise.information(),
        })
    }

    pub(super) fn innovation_cov(&self, held: &Held) -> Matrix4<f64> {
        held.h * self.cov * held.h.transpose() + held.r
    }

    /// Update with one linearised sample in information form (the information gained is
    /// added, never subtracted: a force row carries 10⁸ times the information of the prior
    /// in its direction, where the covariance form loses its positive definiteness); its
    /// normalised innovation.
    pub(super) fn apply(&mut self, held: &Held) -> f64 {
        let nis = self.nis(held);
        let Some(prior) = self.cov.cholesky() else {
            return f64::NAN;
        };
        let ht_w = held.h.transpose() * held.info;
        let info = prior.inverse() + ht_w * held.h;
        let info = (info + info.transpose()) * 0.5;
        let Some(post) = info.cholesky() else {
            return f64::NAN;
        };
        let dx: SVector<f64, N_STATE> = post.solve(&(ht_w * held.y));
        let d = scale();
        for i in 0..N_PARAMS {
            self.p[i] += dx[i] * d[i];
        }
        self.dk += dx[STIFFNESS] * d[STIFFNESS];
        let cov = post.inverse();
        self.cov = (cov + cov.transpose()) * 0.5;
        self.track_change(held);
        self.applied += 1;
        nis
    }

    /// The change's covariance and the creep responses through one update's gain (see
    /// [`ChangeTrack`]).
    fn track_change(&mut self, held: &Held) {
        let h = &held.h;
        let k = self.cov * h.transpose() * held.info;
        let kh = k * h;
        let a = Covariance::identity() - kh;
        let t = self.last_t.unwrap_or(0.0);
        let seen = self
            .noise_seen
            .get_or_insert_with(|| ForceNoise::stated(&held.r));
        seen.add(&held.y);
        let krk = k * seen.covariance() * k.transpose();
        self.change.advance(&a, &kh, &krk, t, self.temp_c);
    }

    /// Normalised innovation of a linearised sample.
    fn nis(&self, held: &Held) -> f64 {
        let s = self.innovation_cov(held);
        let s = (s + s.transpose()) * 0.5;
        s.cholesky()
            .map_or(f64::INFINITY, |c| held.y.dot(&c.solve(&held.y)))
    }

    /// One decimated sample of the drives: predict, gate, update (or hold, or find a step);
    /// while a step is "this or that", both estimates predict the sample first and the
    /// evidence may tell them apart ([`UpdateOutcome::Resolved`]).
    pub fn update(&mut self, sample: &ForceSample) -> Result<UpdateOutcome, ElasticError> {
        let (held, named) = self.predicted(sample)?;
        let Some(mut tie) = self.tie.take() else {
            return self.decide(sample, &held, named.nis);
        };
        let Ok((alt_held, runner_up)) = tie.alt.predicted(sample) else {
            // the runner-up's model found no equilibrium here: a solver's failure is no
            // evidence about the machine, and the sample counts for neither
            tie.evidence.neither += 1;
            return self.after_tie(tie, sample, &held, named.nis);
        };
        tie.evidence
            .add(sample.t, sample.q, named, runner_up, GATE_CHI2_4);
        if tie.evidence.verdict(self.opts.tie_evidence_chi2) == Verdict::RunnerUp {
            std::mem::swap(self, &mut tie.alt);
            tie.swapped = true;
            return self.after_tie(tie, sample, &alt_held, runner_up.nis);
        }
        // the runner-up's estimate failing to take the sample is its own trouble, not the
        // named estimate's: the tie stays open, the sample counted for neither
        if tie.alt.decide(sample, &alt_held, runner_up.nis).is_err() {
            tie.evidence.neither += 1;
        }
        self.after_tie(tie, sample, &held, named.nis)
    }
}
