//! Ties: a step explained alike by two parameters, the two estimates' predictions until the
//! evidence parts them, and the motion that would.

use super::estimator::{ForceSample, Held, OnlineEstimator, OpenTie, TieResolved, UpdateOutcome};
use super::options::{GATE_CHI2_4, N_STATE, TIE_MOTION_POSES};
use crate::calib::tie::{plan_motion, SeparatingMotion, TieCandidate, TiePrediction, Verdict};
use crate::elastic::{ElasticError, ALL_ACTIVE};

/// A prediction that missed: the estimate has no innovation covariance for the sample.
const MISSED: TiePrediction = TiePrediction {
    nis: f64::INFINITY,
    ln_det: 0.0,
};

impl OnlineEstimator {
    /// The motion that would settle the open tie: poses of `targets` (x, y mm) in order,
    /// chosen where the two estimates' predicted forces differ most against what either
    /// could make of the difference with its uncertain parameters ([`plan_motion`]), until
    /// the evidence expected is four times [`OnlineOptions::tie_evidence_chi2`] (the
    /// evidence a motion gives spreads by about twice its square root: short of the
    /// threshold less than once in 10⁴) or [`TIE_MOTION_POSES`] poses. None without an open tie or a
    /// reachable target.
    pub fn tie_motion(&self, targets: &[(f64, f64)]) -> Option<SeparatingMotion> {
        let tie = self.tie.as_ref()?;
        let mut named = self.clone();
        named.tie = None;
        let t = self.last_t.unwrap_or(0.0);
        let candidates: Vec<TieCandidate<N_STATE>> = targets
            .iter()
            .filter_map(|&(x, y)| {
                let q = crate::geometry::igm(&self.p, crate::params::Model::M29, x, y)
                    .ok()?
                    .q();
                let other = crate::elastic::fegm(&tie.alt.p, &tie.alt.stiffness(), q, ALL_ACTIVE)
                    .ok()?
                    .drive_force;
                // linearised against the runner-up's forces: the innovation is what the
                // named estimate's prediction misses of them
                let held = named.linearise(&ForceSample { t, q, f: other }).ok()?;
                Some(TieCandidate {
                    x,
                    y,
                    h: held.h,
                    r: held.r,
                    apart: -held.y,
                })
            })
            .collect();
        plan_motion(
            &candidates,
            &self.cov,
            4.0 * self.opts.tie_evidence_chi2,
            TIE_MOTION_POSES,
        )
    }
}

impl OnlineEstimator {
    /// The sample through the estimate that stands after the tie's evidence: the resolution
    /// when the evidence decided it (unless the sample itself ends a step, which ends the
    /// tie), else the tie stays open.
    pub(super) fn after_tie(
        &mut self,
        tie: Box<OpenTie>,
        sample: &ForceSample,
        held: &Held,
        nis: f64,
    ) -> Result<UpdateOutcome, ElasticError> {
        let verdict = tie.evidence.verdict(self.opts.tie_evidence_chi2);
        if verdict == Verdict::Open {
            self.tie = Some(tie);
            return self.decide(sample, held, nis);
        }
        let out = self.decide(sample, held, nis)?;
        if matches!(out, UpdateOutcome::Step(_)) {
            return Ok(out);
        }
        // the estimate moved where the runner-up stood: the drift test starts again
        if tie.swapped {
            self.rebase_change();
        }
        let at = tie
            .evidence
            .decisive
            .and_then(|d| self.tcp(d.q).ok())
            .map(|(x, _)| (x[0], x[1]));
        let (kept, ruled_out) = if tie.swapped {
            (tie.runner_up, tie.named)
        } else {
            (tie.named, tie.runner_up)
        };
        Ok(UpdateOutcome::Resolved(TieResolved {
            param: kept.0,
            change: kept.1,
            ruled_out: ruled_out.0,
            since_s: tie.since_s,
            swapped: tie.swapped,
            evidence: tie.evidence,
            at,
        }))
    }

    /// Predicts the sample at the estimate (after the drift allowed since the last): its
    /// linearised rows and how well the estimate predicted it.
    pub(super) fn predicted(
        &mut self,
        sample: &ForceSample,
    ) -> Result<(Held, TiePrediction), ElasticError> {
        self.predict(sample.t);
        let held = self.linearise(sample)?;
        let s = self.innovation_cov(&held);
        let s = (s + s.transpose()) * 0.5;
        let prediction = s.cholesky().map_or(MISSED, |c| TiePrediction {
            nis: held.y.dot(&c.solve(&held.y)),
            ln_det: 2.0 * c.l().diagonal().iter().map(|v| v.ln()).sum::<f64>(),
        });
        Ok((held, prediction))
    }

    /// Gate, update (or hold, or find a step) with a predicted sample.
    pub(super) fn decide(
        &mut self,
        sample: &ForceSample,
        held: &Held,
        nis: f64,
    ) -> Result<UpdateOutcome, ElasticError> {
        if nis <= GATE_CHI2_4 {
            if self.held.len() >= self.opts.step_samples.max(1) {
                // a step the path has moved away from: named with what was held
                let step = self.step_found();
                let again = self.linearise(sample)?;
                self.apply(&again);
                return Ok(UpdateOutcome::Step(step));
            }
            // fewer gated samples than a step: outliers
            self.outliers += self.held.len();
            self.held.clear();
            return Ok(UpdateOutcome::Applied {
                nis: self.apply(held),
            });
        }
        self.held.push(*held);
        if self.held.len() < self.opts.step_samples.max(1) {
            return Ok(UpdateOutcome::Held { nis });
        }
        let margin = self.attribute_step().margin;
        if margin < self.opts.step_margin && self.held.len() < self.opts.step_max_samples {
            return Ok(UpdateOutcome::Held { nis });
        }
        Ok(UpdateOutcome::Step(self.step_found()))
    }
}
