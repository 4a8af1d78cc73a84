//! The preload's rod forces balanced where the whole model puts the machine: a parallel-holder
//! whose rod 5 is 1.4 mm long tilts the platform by milliradians, and the preload shares
//! itself between rods 4 and 5 by that tilt. Against the twin's truth (its rods at the model's
//! default stiffness: compliance 1, its encoders' noise as drawn), a calibration with
//! `parallelogram` and `preload_elastic` finds the compliance (0.99972 ± 0.00014) and the
//! encoders' noise (0.48 µm against 0.40); balanced on the perfect holder, the same campaign
//! gave the compliance 1.0164 ± 0.0005.

use rpkm_core::calib;
use rpkm_core::campaign::Instrument;
use rpkm_core::diagnose::{calib_options, DiagnosisOptions};
use rpkm_core::effects::{Effect, EffectSet, Parallelogram, PreloadElastic};
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::Params;
use rpkm_twin::{EffectKind, Twin, TwinConfig};

const TWIN_ENCODER_NOISE_MM: f64 = 0.0004;

#[test]
fn a_preload_is_balanced_on_the_parallel_holder_the_model_fits() {
    let mut twin = Twin::new(TwinConfig {
        seed: 132,
        effects: vec![
            (EffectKind::Parallelogram, 1.4),
            (EffectKind::PreloadElastic, 0.5),
        ],
        noise: Some(NoiseModel {
            encoder_mm: TWIN_ENCODER_NOISE_MM,
            ..NoiseModel::default()
        }),
        ..Default::default()
    })
    .expect("twin");
    let campaign = twin
        .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])
        .expect("campaign");
    let effects: [&dyn Effect; 2] = [&Parallelogram, &PreloadElastic::default()];
    let set = EffectSet::bind(&effects, &campaign, &Params::nominal()).expect("binds");
    // the diagnosis's model: rod 5 linked to rod 4, the effect frees it
    let options = calib_options(&DiagnosisOptions::default());
    let (cal, est) = calib::calibrate(&calib::Request {
        effects: &set,
        noise: calib::Noise::ESTIMATE,
        ..calib::Request::new(&campaign, &Params::nominal(), &options)
    })
    .expect("calibrates");
    let compliance = cal
        .effects
        .iter()
        .find(|e| e.name == "compliance")
        .expect("the compliance is in the model");
    assert!(
        (compliance.value - 1.0).abs() < 4.0 * compliance.sigma.max(1e-4),
        "compliance {} ± {} against the twin's 1",
        compliance.value,
        compliance.sigma
    );
    let encoder = est
        .groups
        .iter()
        .find(|g| g.group == "encoder")
        .expect("encoder rows");
    let truth_um = TWIN_ENCODER_NOISE_MM * 1e3;
    assert!(
        encoder.estimated < 2.0 * truth_um,
        "encoder noise estimated {} µm against the twin's {truth_um}",
        encoder.estimated
    );
}
