//! Step changes: the held samples' innovations attributed to the one parameter that best
//! explains them.

use super::estimator::{DetectedStep, OnlineEstimator, OpenTie};
use super::options::{scale, N_STATE};
use crate::calib::tie::TieEvidence;

impl OnlineEstimator {
    /// Names the step of the held samples, applies it, and the held samples after it; with
    /// a runner-up, a second estimate carrying the runner-up's change instead is kept until
    /// the evidence tells the two apart.
    pub(super) fn step_found(&mut self) -> DetectedStep {
        // a new step ends any tie still open
        self.tie = None;
        let mut step = self.attribute_step();
        if step.margin >= self.opts.step_margin {
            step.alternative = None;
        }
        let alt = step.alternative.map(|b| {
            let (change, sigma) = self.one_parameter_fit(b);
            let mut alt = self.clone();
            alt.take_step(b, change, sigma);
            (alt, (b, change))
        });
        self.take_step(step.param, step.change, step.sigma);
        self.tie = alt.map(|(alt, runner_up)| {
            Box::new(OpenTie {
                alt,
                since_s: step.since_s,
                named: (step.param, step.change),
                runner_up,
                evidence: TieEvidence::default(),
                swapped: false,
            })
        });
        // the motion that would settle it, from what the two estimates know now
        step.separating = self.tie_motion(&crate::design::grid_231());
        step
    }

    /// Applies a step of `change` in state `param` (σ `sigma` from the held samples).
    pub(super) fn take_step(&mut self, param: usize, change: f64, sigma: f64) {
        // the step itself, then the held samples through the filter with the parameter's
        // variance opened by a fifth of it (a one-parameter fit of a few poses is close,
        // not exact): spreading the whole step over every parameter the forces see alike
        // would move the ones they cannot tell apart
        self.set_state(param, self.state(param) + change);
        let c = 0.2 * change;
        self.cov[(param, param)] += (c * c + sigma * sigma) / scale()[param].powi(2);
        // the held samples are spent on the step's size: through the filter again they
        // would pull the combinations the forces cannot tell from the step (a start
        // covariance without its correlations leaves them free) and move the TCP
        self.held.clear();
        // a step is reported on its own: the drift test starts again from the estimate with it
        self.rebase_change();
    }

    /// The held samples' least-squares change of state `i` alone (mm, rad or relative) and
    /// its σ, in the forces at the currents' σ (see [`OnlineEstimator::attribute_step`]).
    fn one_parameter_fit(&self, i: usize) -> (f64, f64) {
        let (g, c) = self.held.iter().fold((0.0, 0.0), |(g, c), h| {
            let col = h.h.column(i);
            (g + col.dot(&h.y), c + col.dot(&col))
        });
        let w = self.opts.force_sigma_n.powi(-2);
        let d = scale()[i];
        if c > 0.0 {
            (g / c * d, (w * c).powf(-0.5) * d)
        } else {
            (0.0, f64::INFINITY)
        }
    }

    /// The single state that best explains the held innovations (least squares of each
    /// alone, in the forces themselves at the currents' σ): its change and margin.
    ///
    /// Not weighed by the drives' noise model as the update is: a crash's innovations are
    /// kN, far above any noise, and naming compares the candidates' signatures. The
    /// combinations the encoders' noise enters are where a crash shows; discounting them
    /// left the comparison to the combinations the currents' noise alone enters, where the
    /// rods' signatures are more alike (seed 7's crash of l4: 1.39x better than l5 that
    /// way, 1.78x in N).
    pub(super) fn attribute_step(&self) -> DetectedStep {
        let mut g = [0.0; N_STATE];
        let mut c = [0.0; N_STATE];
        for h in &self.held {
            let w = self.opts.force_sigma_n.powi(-2);
            for i in 0..N_STATE {
                let col = h.h.column(i);
                g[i] += w * col.dot(&h.y);
                c[i] += w * col.dot(&col);
            }
        }
        let gain = |i: usize| if c[i] > 0.0 { g[i] * g[i] / c[i] } else { 0.0 };
        let mut order = self.opts.step_candidates.states();
        order.sort_by(|&a, &b| gain(b).total_cmp(&gain(a)));
        let best = order[0];
        let next = order.get(1).copied().unwrap_or(best);
        let d = scale()[best];
        DetectedStep {
            param: best,
            change: g[best] / c[best] * d,
            sigma: c[best].powf(-0.5) * d,
            since_s: self.held[0].sample.t,
            margin: gain(best) / gain(next).max(f64::MIN_POSITIVE),
            // the runner-up, kept by the caller only while the margin is not clear
            alternative: (next != best).then_some(next),
            separating: None,
        }
    }
}
