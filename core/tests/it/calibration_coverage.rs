//! Does a calibration's covariance cover its parameters' errors (issue 15)? The online tracker
//! starts from the offline calibration's posterior: a covariance that understates the error
//! makes every later check of "within 3σ of the truth" fail for the start's sake.
//!
//! Sixteen twin machines, each with its own seed and its own conventions drawn at random (the
//! preload's size, the currents', encoders' and tracker's noise levels, none of them the
//! levels the calibration assumes), measured with the instrument part of the online test's
//! start campaign (the laser tracker, loaded, and self-calibration) and calibrated as a user
//! would: `preload_elastic` in the model (what the discovery names) and the noise estimated.
//! Against the twin's true parameters, the errors' Mahalanobis distances errᵀ Σ⁻¹ err follow
//! χ² on the calibrated parameters: median in [18, 38], at most one machine in ten beyond the
//! 99.9 % point, and every parameter's z-score err / σ has an RMS over the machines within
//! the band χ²(16) leaves a right σ for all 29 parameters together with probability 0.99
//! (0.43-1.67: a fixed [0.7, 1.4] fails a right covariance somewhere in 83 % of draws of 16
//! machines).
//!
//! With the start campaign's 200 production poses (ignored: about 15 s in release) the same
//! checks hold: their drive-force rows carry the encoders' noise (0.2 µm is 10-20 N of force
//! when the drives hold their commands), decorrelated (`noise::DriveNoise`), at a level of
//! its own (the `drive_position` group).
//!
//! What remains (docs/calibration.md, issue 15): the prior holds rods 4 and 5 independent
//! where the twin builds them equal (a perfect parallel-holder), so the pair's sum has twice
//! the prior's variance in the twin: d² runs about 1.2x χ²'s.
//!
//! What the twin shares with the model is physics, not assumptions: its rods are springs and
//! its drives hold their commands with encoder noise; the model balances the recorded forces
//! at the pose it computes and weighs the rows by the noise the campaign shows.
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rpkm_core::calib;
use rpkm_core::calib::{Calibration, Options};
use rpkm_core::campaign::Instrument;
use rpkm_core::design;
use rpkm_core::effects::{self, EffectSet};
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{Params, NAMES, N_PARAMS};
use rpkm_core::stats::chi2_upper_tail;
use rpkm_twin::{EffectKind, ThermalPhysics, Twin, TwinConfig};

/// Machines calibrated.
const MACHINES: usize = 16;

/// A twin machine with conventions of its own: `k` seeds the draw.
fn machine(k: u64) -> TwinConfig {
    let mut rng = StdRng::seed_from_u64(0x00c0_7e2a_9e00 + k);
    let noise = NoiseModel {
        force_n: rng.gen_range(2.0..6.0),
        encoder_mm: rng.gen_range(0.1e-3..0.35e-3),
        lt_along_mm: rng.gen_range(3e-3..8e-3),
        lt_across_mm: rng.gen_range(12e-3..30e-3),
        lt_across_per_m_mm: rng.gen_range(0.0..6e-3),
        ..NoiseModel::default()
    };
    let preload = rng.gen_range(0.2..0.4);
    TwinConfig {
        seed: rng.gen(),
        effects: vec![(EffectKind::PreloadElastic, preload)],
        thermal: ThermalPhysics {
            scales_per_k: 0.0,
            ..Default::default()
        },
        noise: Some(noise),
        ..Default::default()
    }
}

/// The online test's start calibration on the machine `cfg`, with `production` of its
/// production poses (all drives active: drive-force rows), and the truth.
fn calibrate(cfg: TwinConfig, production: usize) -> (Calibration, Params) {
    let seed = cfg.seed;
    let mut t = Twin::new(cfg).expect("twin");
    let mut plan = design::for_instrument(Instrument::Lt);
    plan.extend(design::for_instrument(Instrument::SelfCal));
    if production > 0 {
        plan.extend(design::production(production, seed));
    }
    let c = t.run(&plan, "start").expect("start campaign");
    let elastic = effects::by_name("preload_elastic").expect("library effect");
    let set = EffectSet::bind(&[elastic.as_ref()], &c, &Params::nominal()).expect("binds");
    let (cal, _) = calib::calibrate(&calib::Request {
        effects: &set,
        noise: calib::Noise::ESTIMATE,
        ..calib::Request::new(&c, &Params::nominal(), &Options::default())
    })
    .expect("calibrates");
    (cal, *t.true_params())
}

/// The error's Mahalanobis distance under the calibration's covariance over the parameters
/// it calibrated (a non-zero variance), their number, and each one's z-score.
fn mahalanobis(cal: &Calibration, truth: &Params) -> (f64, usize, [Option<f64>; N_PARAMS]) {
    let ids: Vec<usize> = (0..N_PARAMS)
        .filter(|&i| cal.covariance[(i, i)] > 0.0)
        .collect();
    let n = ids.len();
    let cov = nalgebra::DMatrix::from_fn(n, n, |a, b| cal.covariance[(ids[a], ids[b])]);
    let err = nalgebra::DVector::from_fn(n, |a, _| cal.params[ids[a]] - truth[ids[a]]);
    let solved = cov
        .clone()
        .cholesky()
        .expect("a positive definite covariance")
        .solve(&err);
    let mut z = [None; N_PARAMS];
    for (a, &i) in ids.iter().enumerate() {
        z[i] = Some(err[a] / cov[(a, a)].sqrt());
    }
    (err.dot(&solved), n, z)
}

#[test]
fn the_covariance_covers_the_errors_of_twin_machines() {
    check_coverage(0);
}

/// The online test's whole start campaign: its 200 production poses' drive-force rows carry
/// the encoders' noise (`noise::DriveNoise`). About 15 s in release.
#[test]
#[ignore = "16 calibrations with 200 force poses each (about 15 s in release): run with --ignored"]
fn the_covariance_covers_the_errors_with_production_poses() {
    check_coverage(200);
}

/// The checks of the header on the machines calibrated with `production` production poses.
fn check_coverage(production: usize) {
    let mut d2 = Vec::new();
    let mut beyond = 0;
    let mut z2 = [(0.0, 0usize); N_PARAMS];
    for k in 0..MACHINES as u64 {
        let (cal, truth) = calibrate(machine(k), production);
        let (d, n, z) = mahalanobis(&cal, &truth);
        let p = chi2_upper_tail(d, n as f64);
        eprintln!("machine {k}: d² {d:6.1} on {n} parameters, P(χ² beyond) {p:.4}");
        assert!(n >= 27, "only {n} parameters calibrated");
        beyond += usize::from(p < 1e-3);
        d2.push(d);
        for (acc, zi) in z2.iter_mut().zip(z) {
            if let Some(zi) = zi {
                *acc = (acc.0 + zi * zi, acc.1 + 1);
            }
        }
    }
    d2.sort_by(f64::total_cmp);
    let median = 0.5 * (d2[MACHINES / 2 - 1] + d2[MACHINES / 2]);
    eprintln!("d² median {median:.1}, {beyond} of {MACHINES} beyond χ²'s 99.9 % point");
    assert!(
        (18.0..=38.0).contains(&median),
        "median Mahalanobis distance {median:.1}: {d2:.1?}"
    );
    assert!(
        beyond * 10 <= MACHINES,
        "{beyond} of {MACHINES} machines beyond χ²'s 99.9 % point: {d2:.1?}"
    );
    let rms: Vec<(&str, f64)> = z2
        .iter()
        .enumerate()
        .filter(|(_, (_, m))| *m > 0)
        .map(|(i, &(s, m))| (NAMES[i], (s / m as f64).sqrt()))
        .collect();
    // RMS² · M follows χ²(M) for a right σ: the band a right covariance leaves with
    // probability 0.99 for all parameters together (each side 0.005 / n)
    let tail = 0.005 / rms.len() as f64;
    let m = MACHINES as f64;
    let band = (
        (chi2_quantile(1.0 - tail, m) / m).sqrt(),
        (chi2_quantile(tail, m) / m).sqrt(),
    );
    eprintln!("z-score RMS (band {band:.2?}): {rms:.2?}");
    for (name, r) in rms {
        assert!(
            (band.0..=band.1).contains(&r),
            "{name}: z-score RMS {r:.2} over the machines, outside {band:.2?}"
        );
    }
}

/// The x that χ²(ν) exceeds with probability `upper` (bisection on the tail).
fn chi2_quantile(upper: f64, nu: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 20.0 * nu + 100.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if chi2_upper_tail(mid, nu) > upper {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}
