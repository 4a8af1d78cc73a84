//! Telling apart two explanations of a step that the path so far moved alike ("l3 or l1",
//! issue 28).
//!
//! A ratio of how well each explains the held samples cannot do it: where the rods' force
//! signatures are 0.98 alike, the best pose of the workspace gives a ratio of 1.04 however
//! large the step. What parts them is the evidence against the noise: from the step on, the
//! estimate with the named change and the one with the runner-up's each predict every
//! sample before using it, and what each prediction misses is summed. A prediction is judged
//! on data it has not seen, so neither hypothesis can fit its way out; where both miss a
//! sample (an outlier, a new event), it is no evidence for either and is not counted.

use nalgebra::{Matrix4, SMatrix, SVector, Vector4};
use serde::Serialize;

/// How well one estimate predicted a sample: the normalised innovation and the log
/// determinant of its covariance (−2 log-likelihood up to a constant).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TiePrediction {
    pub nis: f64,
    pub ln_det: f64,
}

impl TiePrediction {
    fn misses(&self) -> f64 {
        self.nis + self.ln_det
    }
}

/// The sample that said most.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Decisive {
    /// Its stream time, s.
    pub t: f64,
    /// The drive positions there, mm.
    pub q: [f64; 4],
    /// Its share of the evidence, χ² (positive: for the named).
    pub chi2: f64,
}

/// The evidence for the named explanation against its runner-up since the step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TieEvidence {
    /// Σ over the counted samples of what the runner-up's prediction missed minus what the
    /// named one's missed (−2 log-likelihood ratio, χ² units): positive favours the named.
    pub chi2: f64,
    /// Samples counted: those at least one of the two predicted within the gate.
    pub counted: usize,
    /// Samples neither predicted within the gate, or the runner-up's model could not solve:
    /// no evidence for either (a counted sample the runner-up's estimate then failed to
    /// take counts here too).
    pub neither: usize,
    /// The counted sample with the largest share.
    pub decisive: Option<Decisive>,
}

/// Where the evidence stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Open,
    /// The named explanation stands alone.
    Named,
    /// The runner-up does.
    RunnerUp,
}

impl TieEvidence {
    /// Adds one sample as the named and the runner-up's estimates predicted it (before
    /// either used it); `gate` is the normalised innovation a prediction must stay within
    /// for the sample to count.
    pub fn add(
        &mut self,
        t: f64,
        q: [f64; 4],
        named: TiePrediction,
        runner_up: TiePrediction,
        gate: f64,
    ) {
        let finite = named.misses().is_finite() || runner_up.misses().is_finite();
        if !finite || named.nis.min(runner_up.nis) > gate {
            self.neither += 1;
            return;
        }
        // an estimate that cannot predict the sample at all (a singular innovation) misses
        // it by more than any gate: the other's sample
        let share = (runner_up.misses().min(f64::MAX) - named.misses().min(f64::MAX))
            .clamp(-f64::MAX, f64::MAX);
        self.chi2 += share;
        self.counted += 1;
        if self.decisive.is_none_or(|d| share.abs() > d.chi2.abs()) {
            self.decisive = Some(Decisive { t, q, chi2: share });
        }
    }

    /// The verdict at `threshold` (χ² of evidence either way).
    pub fn verdict(&self, threshold: f64) -> Verdict {
        if self.chi2 >= threshold {
            Verdict::Named
        } else if self.chi2 <= -threshold {
            Verdict::RunnerUp
        } else {
            Verdict::Open
        }
    }
}

/// A pose the machine could be driven to, as the two estimates see it.
#[derive(Clone, Copy, Debug)]
pub struct TieCandidate<const N: usize> {
    /// The pose, mm.
    pub x: f64,
    pub y: f64,
    /// The forces' rows over the state there (the named estimate's), its forces' noise
    /// covariance, and the two estimates' predicted forces apart (named − runner-up), N.
    pub h: SMatrix<f64, 4, N>,
    pub r: Matrix4<f64>,
    pub apart: Vector4<f64>,
}

/// The motion that tells a tie apart: the poses in order, a sample at each.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SeparatingMotion {
    /// x, y mm, all four drives position-controlled.
    pub poses: Vec<(f64, f64)>,
    /// The evidence the samples there would give together, χ² either way (its σ under
    /// noise is about twice its square root).
    pub chi2: f64,
    /// The evidence one sample at the first pose alone would give, χ².
    pub first_chi2: f64,
}

/// Chooses up to `max_poses` of the candidates (greedily, a pose may come again) until
/// the evidence expected reaches `enough`: the two predictions' difference at each pose
/// less what the state's uncertainty (`cov`, the named estimate's) predicts of it from
/// the poses before, weighed by that prediction's covariance. A difference the uncertain
/// parameters reproduce is no evidence: in the linear-Gaussian approximation the sum is
/// exactly the expected −2 log-likelihood ratio of the two over the motion. None without
/// candidates.
pub fn plan_motion<const N: usize>(
    candidates: &[TieCandidate<N>],
    cov: &SMatrix<f64, N, N>,
    enough: f64,
    max_poses: usize,
) -> Option<SeparatingMotion> {
    let mut cov = *cov;
    // what the motion so far tells of the state from the differences (ideally)
    let mut known = SVector::<f64, N>::zeros();
    let mut motion = SeparatingMotion {
        poses: Vec::new(),
        chi2: 0.0,
        first_chi2: 0.0,
    };
    while motion.poses.len() < max_poses && motion.chi2 < enough {
        let gain = |c: &TieCandidate<N>| {
            let s = c.h * cov * c.h.transpose() + c.r;
            let left = c.apart - c.h * known;
            s.cholesky().map_or(0.0, |ch| left.dot(&ch.solve(&left)))
        };
        let (best, g) = candidates
            .iter()
            .map(|c| (c, gain(c)))
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        if motion.poses.is_empty() {
            motion.first_chi2 = g;
        }
        motion.poses.push((best.x, best.y));
        motion.chi2 += g;
        // the state's information with the pose's sample (information form: the forces
        // carry far more than the prior in their directions)
        let Some(r_info) = best.r.try_inverse() else {
            break;
        };
        let Some(prior) = cov.try_inverse() else {
            break;
        };
        let info = prior + best.h.transpose() * r_info * best.h;
        let Some(post) = info.try_inverse() else {
            break;
        };
        known += post * best.h.transpose() * r_info * (best.apart - best.h * known);
        cov = (post + post.transpose()) * 0.5;
    }
    Some(motion)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(nis: f64) -> TiePrediction {
        TiePrediction { nis, ln_det: 0.0 }
    }

    #[test]
    fn a_sample_neither_predicts_is_not_evidence() {
        let mut e = TieEvidence::default();
        // an outlier: both miss by far, one by more
        e.add(1.0, [0.0; 4], p(4.0e4), p(9.0e4), 33.4);
        assert_eq!((e.counted, e.neither, e.chi2), (0, 1, 0.0));
        assert_eq!(e.verdict(30.0), Verdict::Open);
    }

    /// The motion's evidence is the batch −2 log-likelihood ratio of its samples,
    /// Δᵀ (H P Hᵀ + R)⁻¹ Δ: one state of prior variance p read with unit noise, at pose 1
    /// where the two explanations differ by d and at pose 0 where they agree.
    /// - Pose 1 twice: 2d² / (2p + 1), not twice one sample's d² / (p + 1) (the two share
    ///   the state's error).
    /// - Pose 1, then pose 0: d² (p + 1) / (2p + 1). A pose where both predict the same
    ///   pins the uncertain state, so that the difference at pose 1 is no longer absorbed;
    ///   the planner chooses it second, over pose 1 again.
    #[test]
    fn a_motion_expects_the_batch_evidence_of_its_samples() {
        let (p, d) = (4.0, 3.0);
        let pose = |x: f64, apart: f64| TieCandidate::<1> {
            x,
            y: 0.0,
            h: SMatrix::<f64, 4, 1>::new(1.0, 0.0, 0.0, 0.0),
            r: Matrix4::identity(),
            apart: Vector4::new(apart, 0.0, 0.0, 0.0),
        };
        let cov = SMatrix::<f64, 1, 1>::new(p);
        let plan = |poses: &[TieCandidate<1>]| {
            plan_motion(poses, &cov, f64::INFINITY, 2).expect("a motion")
        };
        let twice = plan(&[pose(1.0, d)]);
        assert_eq!(twice.poses, [(1.0, 0.0), (1.0, 0.0)]);
        assert!(
            (twice.first_chi2 - d * d / (p + 1.0)).abs() < 1e-12,
            "{twice:?}"
        );
        assert!(
            (twice.chi2 - 2.0 * d * d / (2.0 * p + 1.0)).abs() < 1e-12,
            "{twice:?}"
        );
        let pinned = plan(&[pose(0.0, 0.0), pose(1.0, d)]);
        assert_eq!(pinned.poses, [(1.0, 0.0), (0.0, 0.0)]);
        let batch = d * d * (p + 1.0) / (2.0 * p + 1.0);
        assert!((pinned.chi2 - batch).abs() < 1e-12, "{pinned:?}");
    }

    #[test]
    fn the_runner_up_that_predicts_better_wins() {
        let mut e = TieEvidence::default();
        e.add(1.0, [0.0; 4], p(4.0), p(5.0), 33.4);
        e.add(2.0, [1.0; 4], p(4.5e4), p(3.0), 33.4);
        assert_eq!(e.counted, 2);
        assert!((e.chi2 - (1.0 - 44_997.0)).abs() < 1e-9);
        assert_eq!(e.decisive.map(|d| d.t), Some(2.0));
        assert_eq!(e.verdict(30.0), Verdict::RunnerUp);
    }
}
