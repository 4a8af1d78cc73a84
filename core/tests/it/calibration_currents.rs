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

use rpkm_core::calib;
use rpkm_core::calib::{Calibration, Options, Selection};
use rpkm_core::campaign::{Campaign, Instrument, MeasuredPose};
use rpkm_core::design;
use rpkm_core::effects::{
    Corrections, Effect, EffectSet, PreloadElastic, StiffnessFactor, Thermal,
};
use rpkm_core::elastic::Stiffness;
use rpkm_core::noise::NoiseModel;
use rpkm_core::obs::{self, Step};
use rpkm_core::params::{Model, Params, NAMES};
use rpkm_twin::{EffectKind, Twin, TwinConfig};

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
    let (cal, _) = calib::calibrate(&calib::Request {
        effects: &none,
        noise: calib::Noise::ESTIMATE,
        ..calib::Request::new(c, &start, &Options::default())
    })
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
    assert!(production.poses.iter().all(MeasuredPose::drives_loaded));
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

/// A twin whose true stiffness is `factor` times the model's default.
fn twin_with_stiffness(seed: u64, factor: f64) -> Twin {
    let elastic = EffectKind::PreloadElastic;
    Twin::new(TwinConfig {
        seed,
        effects: vec![(elastic, elastic.default_magnitude())],
        stiffness: Stiffness::default().scaled(factor),
        noise: Some(NoiseModel {
            force_n: TWIN_FORCE_NOISE_N,
            ..NoiseModel::default()
        }),
        ..Default::default()
    })
    .expect("twin")
}

fn calibrate_with(c: &Campaign, effects: &[&dyn Effect]) -> Calibration {
    let set = EffectSet::bind(effects, c, &Params::nominal()).expect("binds");
    let (cal, _) = calib::calibrate(&calib::Request {
        effects: &set,
        noise: calib::Noise::ESTIMATE,
        ..calib::Request::new(c, &Params::nominal(), &Options::default())
    })
    .expect("calibrates");
    cal
}

/// The forces are the stiffness times the incompatibility: alone they cannot tell a softer
/// machine from a geometry further from its controller's (calibration_currents_observability
/// shows it); the followers of a self-calibration measure the incompatibility in mm, so
/// forces and followers in one campaign give the stiffness, and it lies within 3σ of the
/// twin's (10 % softer than the model's default).
#[test]
fn forces_and_followers_in_one_campaign_find_the_stiffness() {
    const TRUE_FACTOR: f64 = 0.9;
    let mut t = twin_with_stiffness(29, TRUE_FACTOR);
    let truth = *t.true_params();
    let mut plan = design::for_instrument(Instrument::SelfCal);
    plan.extend(design::production(300, 29));
    let mixed = t.run(&plan, "self + production").expect("mixed campaign");
    assert!(mixed.poses.iter().any(MeasuredPose::drives_loaded));
    assert!(mixed
        .poses
        .iter()
        .any(|p| p.instrument == Instrument::SelfCal));
    let cal = calibrate_with(&mixed, &[&StiffnessFactor]);
    let k = &cal.effects[0];
    assert!(
        k.identified,
        "stiffness held: observability {}",
        k.observability
    );
    let z = (k.value - (TRUE_FACTOR - 1.0)) / k.sigma;
    assert!(
        z.abs() < 3.0 && k.sigma < 0.02,
        "stiffness change {:.4} ± {:.4}, truth {:.2} ({z:.2}σ)",
        k.value,
        k.sigma,
        TRUE_FACTOR - 1.0
    );
    for (i, value, sigma) in determined(&cal) {
        let z = (value - truth[i]) / sigma;
        assert!(z.abs() < 3.0, "{}: {z:.2}σ from the truth", NAMES[i]);
    }
    eprintln!(
        "stiffness change {:.4} ± {:.4} (truth {:.2})",
        k.value,
        k.sigma,
        TRUE_FACTOR - 1.0
    );
}

/// The effects' columns of the force rows (the chain rule through the force model's
/// sensitivities to p, q and the stiffness) against central differences of the force rows
/// themselves, for a temperature that lengthens rods and frame and for the stiffness.
#[test]
fn effect_columns_of_the_force_rows_match_finite_differences() {
    let mut t = Twin::new(TwinConfig {
        seed: 31,
        effects: vec![
            (EffectKind::PreloadElastic, 0.3),
            (EffectKind::Thermal, 3.0),
        ],
        ..Default::default()
    })
    .expect("twin");
    let c = t
        .run(&design::production(20, 31), "production")
        .expect("production");
    let p = Params::nominal();
    let thermal = Thermal::default();
    let set = EffectSet::bind(&[&thermal, &StiffnessFactor], &c, &p).expect("binds");
    let layout = set.layout();
    let theta: Vec<f64> = layout.iter().map(|l| 0.7 * l.param.prior).collect();
    let rows_at = |theta: &[f64]| {
        obs::residuals_with(
            &c,
            &p,
            Model::M29,
            Step::Direct,
            &p,
            &set.corrections(theta, &p),
            &NoiseModel::default(),
        )
        .expect("force rows")
    };
    let rows = rows_at(&theta);
    assert_eq!(rows.len(), 4 * 20);
    for k in 0..theta.len() {
        // an anchored term's prior is a fraction of a millikelvin: a hundredth of it would
        // leave the differences in the forces' rounding
        let h = layout[k].param.prior
            * if layout[k].param.anchor.is_some() {
                1.0
            } else {
                1e-2
            };
        let (mut tp, mut tm) = (theta.clone(), theta.clone());
        tp[k] += h;
        tm[k] -= h;
        let (rp, rm) = (rows_at(&tp), rows_at(&tm));
        let mut checked = 0;
        for (i, r) in rows.iter().enumerate() {
            let fd = (rp[i].value - rm[i].value) / (2.0 * h);
            let tol = 1e-3 * r.d_theta[k].abs().max(1.0);
            assert!(
                (fd - r.d_theta[k]).abs() <= tol,
                "{}.{} row {i} ({}): chain rule {} vs differences {fd}",
                layout[k].effect,
                layout[k].param.name,
                r.direction,
                r.d_theta[k]
            );
            checked += usize::from(r.d_theta[k].abs() > 1.0);
        }
        assert!(checked > 0, "{}: no force moved", layout[k].param.name);
    }
}

/// On a campaign of drive-force rows alone the effect has no instrument row to correct (the
/// force rows stretch the rods by their own forces): refused with the first force row.
#[test]
fn preload_elastic_is_refused_on_force_rows() {
    let mut t = twin(37);
    let c = t
        .run(&design::production(5, 37), "production")
        .expect("production");
    let err = EffectSet::bind(&[&PreloadElastic::default()], &c, &Params::nominal())
        .expect_err("refused");
    assert_eq!(err.effect, "preload_elastic");
    assert!(
        err.reason.contains("production:2") && err.reason.contains("only drive-force rows"),
        "{err}"
    );
}

/// The calibration's force rows are the four forces of each pose turned into the
/// combinations the drives' noise is diagonal in (`noise::DriveNoise`): an orthonormal turn,
/// so each pose keeps its sum of squares and its information JᵀJ at equal weights; two
/// combinations carry the encoders' share (`drive_position`), two the currents' noise alone.
#[test]
fn the_force_rows_turn_into_the_drives_noise_modes() {
    let mut t = twin(11);
    let c = t
        .run(&design::production(12, 11), "prod")
        .expect("production campaign");
    let p = Params::nominal();
    let noise = NoiseModel::default();
    let thesis = obs::residuals(&c, &p, Model::M29, Step::Direct, &p, &noise).expect("rows");
    let modes = obs::residuals_with(
        &c,
        &p,
        Model::M29,
        Step::Direct,
        &p,
        &Corrections::default(),
        &noise,
    )
    .expect("rows");
    assert_eq!(thesis.len(), modes.len());
    let (force, drive) = (
        rpkm_core::noise::Group::Force.index(),
        rpkm_core::noise::Group::DrivePosition.index(),
    );
    for (f, m) in thesis.chunks(4).zip(modes.chunks(4)) {
        let names: Vec<String> = m.iter().map(|r| r.direction.to_string()).collect();
        assert_eq!(names, ["fmode1", "fmode2", "fmode3", "fmode4"]);
        let ss = |rows: &[obs::Residual]| rows.iter().map(|r| r.value * r.value).sum::<f64>();
        assert!((ss(f) - ss(m)).abs() <= 1e-9 * ss(f), "{} {}", ss(f), ss(m));
        let info = |rows: &[obs::Residual]| {
            rows.iter()
                .map(|r| r.jacobian * r.jacobian.transpose())
                .fold(nalgebra::SMatrix::<f64, 29, 29>::zeros(), |a, b| a + b)
        };
        let (a, b) = (info(f), info(m));
        assert!((a - b).norm() <= 1e-9 * a.norm());
        // 0.2 µm through the rods' stiffness: N in the first two, in the others a hundredth
        // of the currents' σ at most (K's rank is two up to its central differences)
        let share: Vec<f64> = m.iter().map(|r| r.parts[drive].sqrt()).collect();
        assert!(share[0] >= share[1] && share[1] > 1.0, "{share:?}");
        let floor = 0.01 * noise.force_n;
        assert!(share[2] < floor && share[3] < floor, "{share:?}");
        assert!(m.iter().all(|r| (r.parts[force] - 25.0).abs() < 1e-12));
    }
}
