//! `parallelogram`: the imperfect parallel-holder (thesis 4.1, model 24 → 29). Model 24 makes
//! rod 5 follow rod 4 exactly (the platform keeps its angle); on a real machine rod 5 differs
//! in length and joint positions, the platform tilts over the workspace, and every instrument
//! sees it. The effect frees rod 5: its parameters are rod 5's deviations from the perfect
//! holder.

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::Campaign;
use crate::params::{Params, L5, XA5R, XB5R, YA5R, YB5R};

/// See the module documentation.
pub struct Parallelogram;

/// Rod 5's parameters, in the order of the effect's parameters.
const ROD5: [(usize, &str); 5] = [
    (L5, "dl5"),
    (XA5R, "dxa5r"),
    (YA5R, "dya5r"),
    (XB5R, "dxb5r"),
    (YB5R, "dyb5r"),
];

impl Effect for Parallelogram {
    fn name(&self) -> &'static str {
        super::family::Family::Parallelogram.name()
    }
    fn summary(&self) -> &'static str {
        "imperfect parallel-holder: rod 5 deviates from rod 4 (model 24 to model 29)"
    }
    fn bind(&self, _: &Campaign, _: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        Ok(Box::new(Bound5 {
            params: ROD5
                .iter()
                // a holder off a parallelogram by a centimetre is another mechanism, not an error
                .map(|(_, n)| EffectParam::new(*n, "mm", 0.1).within(-10.0, 10.0))
                .collect(),
        }))
    }
}

struct Bound5 {
    params: Vec<EffectParam>,
}

impl Bound for Bound5 {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, _: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        for (k, (i, _)) in ROD5.iter().enumerate() {
            value.dp[*i] += theta[k];
            partials[k].dp[*i] += 1.0;
        }
    }
}
