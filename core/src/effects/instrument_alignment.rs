//! `instrument_alignment`: the frame of a two-coordinate instrument (laser tracker, grid
//! encoder) rotated about z against the machine, one angle per setup (mrad): the instrument
//! records R(θ) times the true displacement. The angles belong to the setups, not to the
//! machine: held-out data re-fit their own (as the registration of a tracker does).

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::{Campaign, Instrument};
use crate::params::Params;
use crate::units::{rad_from_mrad, RAD_PER_MRAD};
use nalgebra::Vector2;

/// See the module documentation.
pub struct InstrumentAlignment;

impl Effect for InstrumentAlignment {
    fn name(&self) -> &'static str {
        super::family::Family::InstrumentAlignment.name()
    }
    fn summary(&self) -> &'static str {
        "rotation about z of each laser-tracker or grid-encoder setup"
    }
    fn bind(&self, campaign: &Campaign, _: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        let mut params = Vec::new();
        let mut setup_of = vec![None; campaign.poses.len()];
        for setup in campaign.setups() {
            if !matches!(setup.instrument, Instrument::Lt | Instrument::Kgm) {
                continue;
            }
            for &i in &setup.poses {
                setup_of[i] = Some(params.len());
            }
            params.push(EffectParam::new(format!("theta_{}", setup.id), "mrad", 0.1));
        }
        if params.is_empty() {
            return Err(NotApplicable {
                effect: "instrument_alignment".into(),
                reason: "no laser-tracker or grid-encoder setup in the campaign".to_owned(),
            });
        }
        let m = campaign
            .poses
            .iter()
            .map(|p| Vector2::new(p.x.unwrap_or(0.0), p.y.unwrap_or(0.0)))
            .collect();
        Ok(Box::new(BoundAlign {
            params,
            setup_of,
            m,
        }))
    }
}

struct BoundAlign {
    params: Vec<EffectParam>,
    /// Parameter index of each pose's setup (None: not a 2-D instrument).
    setup_of: Vec<Option<usize>>,
    /// Recorded (x, y) per pose.
    m: Vec<Vector2<f64>>,
}

impl Bound for BoundAlign {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    fn setup_local(&self) -> bool {
        true
    }
    fn touched(&self, pose: usize) -> std::ops::Range<usize> {
        // only the pose's own setup's angle moves it
        match self.setup_of.get(pose).copied().flatten() {
            Some(k) => k..k + 1,
            None => 0..0,
        }
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        let Some(k) = self.setup_of[pose] else { return };
        let th = rad_from_mrad(theta[k]);
        let m = self.m[pose];
        let (s, c) = th.sin_cos();
        // true = R(−θ) m
        let t = Vector2::new(c * m.x + s * m.y, -s * m.x + c * m.y);
        value.dm += t - m;
        partials[k].dm += Vector2::new(-s * m.x + c * m.y, -c * m.x - s * m.y) * RAD_PER_MRAD;
    }
}
