//! Calibration from the drive forces alone (issue 15, offline): a machine working with all
//! four drives position-controlled, no instrument, only its recorded drive forces. Against
//! the twin's true machine:
//! - the parameters the forces determine on their own (posterior σ below a third of the
//!   tolerance) lie within 3σ of their true values, and within their uncertainties of a
//!   follower-mode self-calibration of the same machine where that determines them too;
//! - the calibrated model predicts the drive forces of held-out production poses (measured
//!   later, at another temperature) to within three times their noise, where the nominal
//!   model misses them by kilonewtons.
//!
//! The twin's force noise (3 N) is not the model's stated one (5 N): the noise estimation
//! must find it. Known limits of this check: the twin's forces come from the same spring
//! model the calibration inverts, with the model's default stiffness (the stiffness scale is
//! not yet an unknown).

use rpkm_core::calib::{Calibration, Options, Selection};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::design;
use rpkm_core::effects::{Corrections, EffectSet};
use rpkm_core::noise::NoiseModel;
use rpkm_core::obs::{self, Step};
use rpkm_core::params::{Model, Params, NAMES};
use rpkm_core::twin::{EffectKind, Twin, TwinConfig};
use rpkm_core::variance;

const TWIN_FORCE_NOISE_N: f64 = 3.0;

fn twin(seed: u64) -> Twin {
    let elastic = EffectKind::PreloadElastic;
    Twin::new(TwinConfig {
        seed,
        effects: vec![(elastic, elastic.default_magnitude())],
        noise: Some(NoiseModel {
            force_n: TWIN_FORCE_NOISE_N,
            ..NoiseModel::default()
        }),
        ..Default::default()
    })
    .expect("twin")
}

fn calibrate(c: &Campaign) -> Calibration {
    let start = Params::nominal();
    let none = EffectSet::empty();
    let (cal, _) = variance::calibrate_estimating_noise(c, &start, &Options::default(), &none)
        .expect("calibrates");
    cal
}

/// The parameters a calibration determines on their own: posterior σ below a third of the
/// tolerance prior's.
fn determined(cal: &Calibration) -> Vec<(usize, f64, f64)> {
    let Selection::Prior(prior) = Options::default().selection else {
        panic!("the default selection is the tolerance prior");
    };
    cal.identified
        .iter()
        .filter(|id| id.sigma < prior.sigma(id.index) / 3.0)
        .map(|id| (id.index, id.value, id.sigma))
        .collect()
}

/// RMS (N) of the drive-force rows of `c` under parameters `p`.
fn force_rms(c: &Campaign, p: &Params) -> f64 {
    let rows = obs::residuals_with(
        c,
        p,
        Model::M29,
        Step::Direct,
        p,
        &Corrections::default(),
        &NoiseModel::default(),
    )
    .expect("held-out rows");
    let f: Vec<f64> = rows
        .iter()
        .filter(|r| r.direction.is_force())
        .map(|r| r.value)
        .collect();
    assert!(!f.is_empty());
    (f.iter().map(|v| v * v).sum::<f64>() / f.len() as f64).sqrt()
}

#[test]
fn the_drive_forces_alone_find_the_true_machine() {
    let mut t = twin(17);
    let truth = *t.true_params();
    let production = t
        .run(&design::production(300, 17), "production")
        .expect("production campaign");
    assert!(production.poses.iter().all(obs::drives_loaded));
    let cal = calibrate(&production);
    let chi2 = cal.chi2_per_dof;
    assert!(
        (0.8..1.25).contains(&chi2),
        "χ²/dof {chi2} at the estimated force noise"
    );
    let by_forces = determined(&cal);
    assert!(
        !by_forces.is_empty(),
        "the forces determine no parameter on its own"
    );
    for &(i, value, sigma) in &by_forces {
        let z = (value - truth[i]) / sigma;
        assert!(
            z.abs() < 3.0,
            "{}: {value:.6} is {z:.2}σ from {:.6}",
            NAMES[i],
            truth[i]
        );
    }

    let held_out = t
        .run(&design::production(100, 18), "held-out production")
        .expect("held-out production");
    let (before, after) = (
        force_rms(&held_out, &Params::nominal()),
        force_rms(&held_out, &cal.params),
    );
    assert!(
        before > 300.0 * TWIN_FORCE_NOISE_N,
        "nominal model: {before:.1} N"
    );
    assert!(
        after < 3.0 * TWIN_FORCE_NOISE_N,
        "calibrated: {after:.2} N (nominal {before:.0} N)"
    );

    let self_cal = t
        .campaign(&[Instrument::SelfCal, Instrument::SelfCal])
        .expect("self-calibration");
    let by_followers = determined(&calibrate(&self_cal));
    let mut compared = 0;
    for &(i, a, sa) in &by_forces {
        if let Some(&(_, b, sb)) = by_followers.iter().find(|d| d.0 == i) {
            compared += 1;
            let z = (a - b) / (sa * sa + sb * sb).sqrt();
            assert!(
                z.abs() < 3.0,
                "{}: forces {a:.6} ± {sa:.1e}, followers {b:.6} ± {sb:.1e}",
                NAMES[i]
            );
        }
    }
    assert!(compared >= 1, "no parameter determined by both");
}
