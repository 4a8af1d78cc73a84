//! Model discovery on the digital twin: every effect of the library hidden alone is named,
//! ranked first and significant, and adding it brings the held-out error to the noise; no
//! hidden effect gives no verdict; two effects are found one after the other; an effect
//! outside the library (backlash) is reported as unexplained residual pointing at its
//! covariate. The truth is the twin's: which effect it hid, with which magnitude.

use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::diagnose::{self, Diagnosis, Options};
use rpkm_core::effects::{self, Effect};
use rpkm_core::twin::{EffectKind, Twin, TwinConfig};

/// The campaign of these tests: laser tracker (one setup), grid encoder (16 setups) and
/// self-calibration, and 100 held-out laser-tracker poses.
fn campaigns(seed: u64, hidden: &[EffectKind]) -> (Campaign, Campaign) {
    let mut twin = Twin::new(TwinConfig {
        seed,
        effects: hidden.iter().map(|e| (*e, e.default_magnitude())).collect(),
        ..Default::default()
    })
    .expect("twin");
    let cal = twin
        .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])
        .expect("campaign");
    let val = twin.validation(100).expect("validation");
    (cal, val)
}

fn run(cal: &Campaign, val: &Campaign, in_model: &[&str]) -> Diagnosis {
    let boxed: Vec<Box<dyn Effect>> = in_model
        .iter()
        .map(|n| effects::by_name(n).expect("library effect"))
        .collect();
    let refs: Vec<&dyn Effect> = boxed.iter().map(|b| b.as_ref()).collect();
    diagnose::diagnose(cal, Some(val), &refs, &Options::default()).expect("diagnose")
}

fn check_named(effect: EffectKind, seed: u64) {
    let (cal, val) = campaigns(seed, &[effect]);
    let d = run(&cal, &val, &[]);
    let name = effect.as_str();
    let floor = d.baseline.noise_floor_um;
    let before = d.baseline.val_rms_um.expect("held-out RMS");
    eprintln!(
        "{name} seed {seed}: held-out {before:.1} um (floor {floor:.1}), verdict: {}",
        d.verdict
    );
    assert!(
        (15.0..=60.0).contains(&before) && before > 1.2 * floor,
        "{name} seed {seed}: the hidden effect should leave 15-60 um above the noise, got {before:.1} (floor {floor:.1})"
    );
    assert!(!d.baseline.consistent_with_noise, "{name} seed {seed}");
    assert_eq!(
        d.missing_effect.as_deref(),
        Some(name),
        "seed {seed}: {d:#?}"
    );
    let first = &d.candidates[0];
    assert_eq!(first.effect, name);
    assert!(first.significant);
    let after = first.val_rms_after_um.expect("held-out after");
    assert!(
        after <= 1.5 * floor,
        "{name} seed {seed}: held-out after adding it {after:.1} um, floor {floor:.1}"
    );
}

macro_rules! named_test {
    ($test:ident, $effect:expr) => {
        #[test]
        fn $test() {
            for seed in 1..=3 {
                check_named($effect, seed);
            }
        }
    };
}

named_test!(parallelogram_is_named, EffectKind::Parallelogram);
named_test!(preload_elastic_is_named, EffectKind::PreloadElastic);
named_test!(thermal_is_named, EffectKind::Thermal);
named_test!(encoder_scale_is_named, EffectKind::EncoderScale);
named_test!(guide_straightness_is_named, EffectKind::GuideStraightness);
named_test!(
    instrument_alignment_is_named,
    EffectKind::InstrumentAlignment
);

#[test]
fn nothing_missing_without_a_hidden_effect() {
    for seed in 1..=4 {
        let (cal, val) = campaigns(seed, &[]);
        let d = run(&cal, &val, &[]);
        eprintln!("seed {seed}: {}", d.verdict);
        assert_eq!(d.missing_effect, None, "seed {seed}: {d:#?}");
        assert!(d.baseline.consistent_with_noise, "seed {seed}");
        for c in &d.candidates {
            eprintln!(
                "  {} p = {:.2e} expl {:.2}",
                c.effect, c.p_value, c.explained_fraction
            );
        }
        assert!(d.candidates.iter().all(|c| !c.significant), "seed {seed}");
        // and the model then reaches the noise floor on held-out data
        let v = d.baseline.val_rms_um.expect("held-out");
        assert!(v <= 1.2 * d.baseline.noise_floor_um, "seed {seed}: {v}");
    }
}

#[test]
fn two_hidden_effects_are_found_one_after_the_other() {
    let hidden = [EffectKind::Thermal, EffectKind::GuideStraightness];
    for seed in [5, 6] {
        let (cal, val) = campaigns(seed, &hidden);
        let d1 = run(&cal, &val, &[]);
        let first = d1.missing_effect.clone().expect("a first effect");
        let names: Vec<&str> = hidden.iter().map(|e| e.as_str()).collect();
        assert!(
            names.contains(&first.as_str()),
            "seed {seed}: {}",
            d1.verdict
        );
        let d2 = run(&cal, &val, &[&first]);
        let second = d2.missing_effect.clone().expect("a second effect");
        assert!(
            names.contains(&second.as_str()) && second != first,
            "seed {seed}: {} then {}",
            d1.verdict,
            d2.verdict
        );
        let d3 = run(&cal, &val, &[&first, &second]);
        eprintln!("seed {seed}: {first}, then {second}, then: {}", d3.verdict);
        assert_eq!(d3.missing_effect, None, "{}", d3.verdict);
        let after = d3.baseline.val_rms_um.expect("held-out");
        assert!(after <= 1.5 * d3.baseline.noise_floor_um);
    }
}

#[test]
fn backlash_is_unexplained_and_points_at_the_approach_direction() {
    for seed in 1..=3 {
        let (cal, val) = campaigns(seed, &[EffectKind::Backlash]);
        let d = run(&cal, &val, &[]);
        eprintln!("seed {seed}: {}", d.verdict);
        assert!(!d.baseline.consistent_with_noise);
        assert_eq!(d.missing_effect, None, "{}", d.verdict);
        let u = d.unexplained.as_ref().expect("a pointer at the structure");
        assert!(
            u.feature.starts_with("approach_q") && u.r.abs() > 0.8,
            "seed {seed}: {u:?}"
        );
    }
}
