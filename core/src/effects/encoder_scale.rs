//! `encoder_scale`: a scale error of a guide's linear encoders (ppm per guide): the carrier
//! is at q · (1 + s · 1e-6) where the encoder reads q. Guide 2 carries q1 and q4, guide 1 q2
//! and q3. A common scale of all four is close to a change of every rod length and is mostly
//! absorbed by the geometry; a scale that differs between the guides is not.

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::Campaign;
use crate::params::Params;
use crate::units::fraction_from_ppm;

/// See the module documentation.
pub struct EncoderScale;

/// Actuators of guide 1 and of guide 2 (0-based).
const GUIDES: [[usize; 2]; 2] = [[1, 2], [0, 3]];

impl Effect for EncoderScale {
    fn name(&self) -> &'static str {
        super::family::Family::EncoderScale.name()
    }
    fn summary(&self) -> &'static str {
        "scale error of each guide's linear encoders"
    }
    fn bind(&self, campaign: &Campaign, _: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        Ok(Box::new(BoundScale {
            params: ["guide1", "guide2"]
                .iter()
                // a linear scale off by a thousandth reads 1 mm wrong per metre: no scale is
                // that far out
                .map(|g| {
                    EffectParam::new(format!("scale_{g}"), "ppm", 50.0).within(-1000.0, 1000.0)
                })
                .collect(),
            q: campaign.poses.iter().map(|p| p.q).collect(),
        }))
    }
}

struct BoundScale {
    params: Vec<EffectParam>,
    q: Vec<[f64; 4]>,
}

impl Bound for BoundScale {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        for (k, guide) in GUIDES.iter().enumerate() {
            for &a in guide {
                let q = fraction_from_ppm(self.q[pose][a]);
                value.dq[a] += theta[k] * q;
                partials[k].dq[a] += q;
            }
        }
    }
}
