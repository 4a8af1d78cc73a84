//! The twin of the online tracker's tests (issue 15): the preload's elastic effect at its
//! default magnitude, no thermal scale error, drive forces with 3 N of noise.

use rpkm_core::noise::NoiseModel;
use rpkm_twin::{EffectKind, ThermalPhysics, Twin, TwinConfig};

pub fn twin(seed: u64) -> Twin {
    let elastic = EffectKind::PreloadElastic;
    Twin::new(TwinConfig {
        seed,
        effects: vec![(elastic, elastic.default_magnitude())],
        thermal: ThermalPhysics {
            scales_per_k: 0.0,
            ..Default::default()
        },
        noise: Some(NoiseModel {
            force_n: 3.0,
            ..NoiseModel::default()
        }),
        ..Default::default()
    })
    .expect("twin")
}
