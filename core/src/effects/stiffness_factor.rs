//! `stiffness_factor`: the machine's stiffness differs from the model's default by a factor
//! 1 + θ (rods, and carriers where they are compliant, all alike). Only the drive-force rows
//! depend on it (instrument `none`, all drives position-controlled): the deformation of
//! uniformly scaled springs does not depend on their stiffness, so no instrument row sees
//! it; the forces scale with it exactly.
//!
//! What separates it from the geometry: the forces are the stiffness times the
//! incompatibility between the machine's geometry and the controller's, and to first order
//! scaling the stiffness by 1 + θ is the same as scaling the geometry's distance from the
//! controller's by 1 + θ. Forces alone determine it only through the model's nonlinearity
//! (weakly); an instrument that fixes the geometry (mixed rows) separates it
//! (`rpkm analyze observability --method currents` shows both).

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::{Campaign, MeasuredPose};
use crate::params::Params;

/// See the module documentation.
pub struct StiffnessFactor;

/// Plausible relative error of the default stiffness (the prior's scale).
pub const PRIOR: f64 = 0.1;

impl Effect for StiffnessFactor {
    fn name(&self) -> &'static str {
        super::family::Family::StiffnessFactor.name()
    }
    fn summary(&self) -> &'static str {
        "the machine's stiffness relative to the model's default (drive-force rows only)"
    }
    fn bind(&self, campaign: &Campaign, _p: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        if !campaign.poses.iter().any(MeasuredPose::drives_loaded) {
            return Err(NotApplicable {
                effect: "stiffness_factor".into(),
                reason: format!(
                    "the campaign {} has no drive-force row (instrument none, no follower, \
                     f1..f4 recorded): nothing else depends on the stiffness",
                    campaign.source
                ),
            });
        }
        Ok(Box::new(BoundStiffness {
            params: vec![EffectParam::new("change", "x default - 1", PRIOR)],
        }))
    }
}

struct BoundStiffness {
    params: Vec<EffectParam>,
}

impl Bound for BoundStiffness {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, _pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        value.dk += theta[0];
        partials[0].dk += 1.0;
    }
}
