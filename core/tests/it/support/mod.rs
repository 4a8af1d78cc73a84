//! Rigid-geometry campaigns for the calibration tests: a true machine (nominal + seeded
//! errors), a controller commanding igm with the nominal parameters, drives q1, q4 active and
//! q2, q3 followers, instruments and encoders with the noise of `rpkm_core::noise`.
#![allow(dead_code)]

pub mod production;

use nalgebra::{Cholesky, Vector2};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rpkm_core::campaign::{Campaign, Instrument, MeasuredPose};
use rpkm_core::design::PlannedPose;
use rpkm_core::geometry;
use rpkm_core::noise;
use rpkm_core::params::{unit, Model, Params, Unit, N_PARAMS};

pub fn true_params(seed: u64, perfect_parallelogram: bool) -> Params {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut p = Params::nominal();
    for i in 0..N_PARAMS {
        let z: f64 = StandardNormal.sample(&mut rng);
        p[i] += z * if unit(i) == Unit::Rad { 2e-4 } else { 0.1 };
    }
    if perfect_parallelogram {
        p = p.with_perfect_parallelogram();
    }
    p
}

fn gauss(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

/// What the pose's instrument reads: the TCP's displacement `rel` from its setup's reset pose
/// (position, angle), with the default noise model's noise times `k`.
fn read_instrument(
    pose: &mut MeasuredPose,
    rel: Option<(Vector2<f64>, f64)>,
    tcp: Vector2<f64>,
    k: f64,
    rng: &mut StdRng,
) {
    let n_model = noise::NoiseModel::default();
    let zero = pose.reset;
    match pose.instrument {
        Instrument::Lt | Instrument::Kgm => {
            let (d, _) = rel.expect("reset first");
            let xy = noise::XyInstrument::of(pose.instrument).expect("a 2-D instrument");
            let l = Cholesky::new(n_model.xy_covariance(xy, tcp))
                .expect("covariance")
                .l();
            let e = l * Vector2::new(gauss(rng), gauss(rng)) * k;
            let m = if zero { Vector2::zeros() } else { d + e };
            pose.x = Some(m.x);
            pose.y = Some(m.y);
        }
        Instrument::Dbb | Instrument::Circle => {
            let (d, _) = rel.expect("reset first");
            pose.r = Some(if zero {
                0.0
            } else {
                d.norm() + k * n_model.dbb_mm * gauss(rng)
            });
        }
        Instrument::LiX => {
            pose.x = Some(if zero {
                0.0
            } else {
                rel.expect("reset").0.x + k * n_model.li_mm * gauss(rng)
            });
        }
        Instrument::LiY => {
            pose.y = Some(if zero {
                0.0
            } else {
                rel.expect("reset").0.y + k * n_model.li_mm * gauss(rng)
            });
        }
        Instrument::LiPsi => {
            pose.psi = Some(if zero {
                0.0
            } else {
                rel.expect("reset").1 + k * n_model.psi_rad * gauss(rng)
            });
        }
        Instrument::SelfCal | Instrument::None => {}
    }
}

/// Measure `design` on the machine `truth` (model 29 geometry; with a perfect parallel-holder
/// it is also model 24's), with noise if `noisy`.
pub fn measure(
    design: &[PlannedPose],
    truth: &Params,
    seed: u64,
    noisy: bool,
    source: &str,
) -> Campaign {
    let mut rng = StdRng::seed_from_u64(seed ^ 0x5eed);
    let nominal = Params::nominal();
    let k = if noisy { 1.0 } else { 0.0 };
    let n_model = noise::NoiseModel::default();
    let mut poses = Vec::new();
    let mut reset_tcp: Option<(String, Vector2<f64>, f64)> = None;
    for (n, plan) in design.iter().enumerate() {
        let cmd = geometry::igm(&nominal, Model::M29, plan.x, plan.y).expect("target reachable");
        let qc = cmd.q();
        let real = geometry::fgm(truth, Model::M29, qc[0], qc[3]).expect("true machine");
        let q = real.q();
        let tcp = Vector2::new(real.x(), real.y());
        if plan.reset {
            reset_tcp = Some((plan.setup.clone(), tcp, real.psi()));
        }
        let mut pose = MeasuredPose {
            t: n as f64 * 2.0,
            setup: plan.setup.clone(),
            instrument: plan.instrument,
            reset: plan.reset,
            q: [0.0; 4],
            f: [0.0; 4],
            follower: [false, true, true, false],
            x: None,
            y: None,
            r: None,
            psi: None,
            covariates: Vec::new(),
            line: n + 2,
        };
        for (measured, commanded) in pose.q.iter_mut().zip(&q) {
            *measured = commanded + k * n_model.encoder_mm * gauss(&mut rng);
        }
        let rel = reset_tcp
            .as_ref()
            .filter(|r| r.0 == plan.setup)
            .map(|r| (tcp - r.1, real.psi() - r.2));
        read_instrument(&mut pose, rel, tcp, k, &mut rng);
        poses.push(pose);
    }
    Campaign {
        source: source.to_string(),
        comments: Vec::new(),
        covariate_names: Vec::new(),
        poses,
    }
}

/// Random held-out laser-tracker poses.
pub fn validation(truth: &Params, seed: u64) -> Campaign {
    measure(
        &rpkm_core::design::validation(60, seed),
        truth,
        seed + 1,
        true,
        "validation.csv",
    )
}

pub fn rng(seed: u64) -> StdRng {
    let mut r = StdRng::seed_from_u64(seed);
    let _: f64 = r.gen();
    r
}
