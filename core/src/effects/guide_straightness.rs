//! `guide_straightness`: a bowed guide. The carrier joints of a guide are offset across it by
//! a low-order bow of the carrier position, b · 4 (q/L)(1 − q/L) over the span L = 4,000 mm
//! (b: the sagitta, one per guide). The constant and linear parts of a bow are a shift and a
//! rotation of the guide, which the geometric parameters d and γ already describe; the
//! curvature is what they cannot.

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::Campaign;
use crate::params::{Guide, Params, RODS};

/// Span the bow is written over, mm: a guide long enough for every carrier position of the
/// workspace (q ≈ 0.8-2.6 m at its centre). The curvature, not the span, is what is identified.
const SPAN_MM: f64 = 4_000.0;

/// The model's bow shape for a unit sagitta: 4 (q/L)(1 − q/L), zero at both guide ends. Written
/// here, not taken from the simulator: the model's effect form is its own assumption.
fn parabola(q: f64) -> f64 {
    let s = q / SPAN_MM;
    4.0 * s * (1.0 - s)
}

/// See the module documentation.
pub struct GuideStraightness;

impl Effect for GuideStraightness {
    fn name(&self) -> &'static str {
        super::family::Family::GuideStraightness.name()
    }
    fn summary(&self) -> &'static str {
        "bowed guides: carrier joints offset across the guide by a parabola of q"
    }
    fn bind(&self, campaign: &Campaign, _: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        Ok(Box::new(BoundBow {
            params: ["guide1", "guide2"]
                .iter()
                // a guide bowed by more than half a millimetre is a broken machine, not a bow
                .map(|g| EffectParam::new(format!("sagitta_{g}"), "mm", 0.05).within(-0.5, 0.5))
                .collect(),
            q: campaign.poses.iter().map(|p| p.q).collect(),
        }))
    }
}

struct BoundBow {
    params: Vec<EffectParam>,
    q: Vec<[f64; 4]>,
}

impl Bound for BoundBow {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        for rod in &RODS {
            let k = match rod.guide {
                Guide::G1 => 0,
                Guide::G2 => 1,
            };
            let shape = parabola(self.q[pose][rod.actuator]);
            value.dp[rod.xb] += theta[k] * shape;
            partials[k].dp[rod.xb] += shape;
        }
    }
}
