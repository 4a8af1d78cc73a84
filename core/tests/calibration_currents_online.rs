//! Online calibration from the drive forces (issue 15) on the twin's production stream, against
//! the twin's truth over time. The twin does not share the estimator's assumptions: its force
//! noise is 3 N (the estimator states 5 N), its temperature is a ramp with a 15-minute ripple
//! (the estimator knows no temperature law: a random walk), its controller holds nominal-ish
//! parameters the estimator never sees, and a crash bends rod 3 by 0.1 mm at 240 s.
//!
//! Six minutes of stream at 1 kHz, decimated to 10 Hz, with the 4 K of the hour-long stream's
//! drift compressed into them (40 K/h; the estimator's drift rate raised to match): the
//! tracked parameters stay within 3σ of the truth at every check, the drift raises no step,
//! the crash is seen at its first sample, named l3 with its size within 10 s, and the TCP
//! estimate stays near its noise floor (its error over the first minute) while a calibration
//! frozen at the start drifts away. The full hour: `calibration_currents_online_hour`
//! (ignored; figures in docs/calibration.md).
use rpkm_core::calib::online::{ForceSample, OnlineEstimator, OnlineOptions, Outcome};
use rpkm_core::calib::{Calibration, Options};
use rpkm_core::campaign::Instrument;
use rpkm_core::design;
use rpkm_core::effects::EffectSet;
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{index_of, Params, NAMES, N_PARAMS};
use rpkm_core::twin::{
    EffectKind, ProductionConfig, ProductionStream, StepChange, ThermalPhysics, Twin, TwinConfig,
};
use rpkm_core::variance;

fn twin(seed: u64) -> Twin {
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

fn start_calibration(t: &mut Twin, seed: u64) -> Calibration {
    let mut plan = design::for_instrument(Instrument::Lt);
    plan.extend(design::for_instrument(Instrument::SelfCal));
    plan.extend(design::production(200, seed));
    let c = t.run(&plan, "start").expect("start campaign");
    let (cal, _) = variance::calibrate_estimating_noise(
        &c,
        &Params::nominal(),
        &Options::default(),
        &EffectSet::empty(),
    )
    .expect("calibrates");
    cal
}

/// The tracker over a production stream, with what a test checks.
pub struct Run {
    /// Largest |estimate − truth| / σ over the 29 parameters at each check, with its time.
    pub worst_z: Vec<(f64, f64, usize)>,
    /// Steps found: time named, the step.
    pub steps: Vec<(f64, rpkm_core::calib::online::StepChange)>,
    /// RMS TCP error per window of `window_s`, online and frozen at the start, mm.
    pub windows: Vec<(f64, f64, f64)>,
}

fn track(
    seed: u64,
    cfg: ProductionConfig,
    opts: OnlineOptions,
    decimate: usize,
    window_s: f64,
) -> Run {
    let mut t = twin(seed);
    let cal = start_calibration(&mut t, seed);
    let mut sigma = [0.0; N_PARAMS];
    for id in &cal.identified {
        sigma[id.index] = id.sigma;
    }
    let mut est = OnlineEstimator::from_sigmas(cal.params, Some(&sigma), opts);
    let frozen = est.clone();
    let step_at = cfg.step.map_or(f64::INFINITY, |s| s.at_s);
    let mut run = Run {
        worst_z: Vec::new(),
        steps: Vec::new(),
        windows: Vec::new(),
    };
    let mut w = (0.0, 0.0, 0usize, window_s);
    let mut named = false;
    for (n, s) in ProductionStream::new(&t, cfg).enumerate() {
        let s = s.expect("production sample");
        if n % decimate != 0 {
            continue;
        }
        let out = est
            .update(&ForceSample {
                t: s.t,
                q: s.q,
                f: s.f,
            })
            .expect("update");
        if let Outcome::Step(st) = out {
            run.steps.push((s.t, st));
            named = true;
        }
        let (tcp, _) = est.tcp(s.q).expect("online tcp");
        let (ftcp, _) = frozen.tcp(s.q).expect("frozen tcp");
        w.0 += (tcp.x - s.tcp[0]).powi(2) + (tcp.y - s.tcp[1]).powi(2);
        w.1 += (ftcp.x - s.tcp[0]).powi(2) + (ftcp.y - s.tcp[1]).powi(2);
        w.2 += 1;
        if s.t >= w.3 {
            run.windows
                .push((w.3, (w.0 / w.2 as f64).sqrt(), (w.1 / w.2 as f64).sqrt()));
            w = (0.0, 0.0, 0, w.3 + window_s);
        }
        // between the crash and its naming the truth has moved and the estimate not yet
        let settled = s.t < step_at || named;
        if n % (10 * decimate) == 0 && settled {
            let worst = (0..N_PARAMS)
                .map(|i| ((est.params()[i] - s.truth[i]).abs() / est.sigma(i), i))
                .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a });
            run.worst_z.push((s.t, worst.0, worst.1));
        }
    }
    run
}

#[test]
fn the_forces_track_a_drifting_machine_and_name_a_crash() {
    let seed = 41;
    let l3 = index_of("l3").expect("l3");
    let cfg = ProductionConfig {
        seconds: 360.0,
        drift_k_per_h: 40.0,
        step: Some(StepChange {
            at_s: 240.0,
            param: l3,
            change: 0.1,
        }),
        seed,
        ..Default::default()
    };
    let opts = OnlineOptions {
        length_drift_mm_per_sqrt_h: 0.15,
        ..OnlineOptions::default()
    };
    let run = track(seed, cfg, opts, 100, 30.0);

    assert!(run.worst_z.len() > 300, "{} checks", run.worst_z.len());
    for &(t, z, i) in &run.worst_z {
        assert!(
            z < 3.0,
            "t = {t:.1} s: {} is {z:.2}σ from the truth",
            NAMES[i]
        );
    }
    assert_eq!(run.steps.len(), 1, "steps: {:?}", run.steps);
    let (named_at, step) = run.steps[0];
    assert_eq!(NAMES[step.param], "l3", "{step:?}");
    assert!(
        (240.0..240.2).contains(&step.since_s),
        "seen at {} s",
        step.since_s
    );
    assert!(named_at - 240.0 <= 10.0, "named at {named_at} s");
    assert!((step.change - 0.1).abs() < 0.02, "size {} mm", step.change);

    // the noise floor: the online estimate's TCP error over the first minute
    let floor = (run.windows[..2].iter().map(|w| w.1 * w.1).sum::<f64>() / 2.0).sqrt();
    for &(end, online, _) in &run.windows[2..] {
        assert!(
            online <= 1.5 * floor,
            "window to {end} s: {:.1} µm, floor {:.1} µm",
            online * 1e3,
            floor * 1e3
        );
    }
    let &(_, online, frozen) = run.windows.last().expect("windows");
    assert!(
        frozen > 1.25 * floor && frozen > 1.5 * online,
        "frozen {:.1} µm, online {:.1} µm, floor {:.1} µm",
        frozen * 1e3,
        online * 1e3,
        floor * 1e3
    );
    eprintln!(
        "floor {:.1} µm; last window online {:.1} µm, frozen {:.1} µm; worst {:.2}σ; step {} {:+.4} mm named {:.1} s after",
        floor * 1e3, online * 1e3, frozen * 1e3,
        run.worst_z.iter().map(|w| w.1).fold(0.0, f64::max),
        NAMES[step.param], step.change, named_at - 240.0
    );
}

/// The full figure: one hour at 1 kHz, 4 K of drift, decimated to 10 Hz, a crash at 40 min.
/// Minutes in a release build: `cargo test --release -p rpkm-core --test
/// calibration_currents_online -- --ignored --nocapture`.
#[test]
#[ignore = "an hour of stream at 1 kHz (about 6 min): run with --ignored"]
fn calibration_currents_online_hour() {
    let seed = 43;
    let l3 = index_of("l3").expect("l3");
    let cfg = ProductionConfig {
        seconds: 3600.0,
        drift_k_per_h: 4.0,
        step: Some(StepChange {
            at_s: 2400.0,
            param: l3,
            change: 0.1,
        }),
        seed,
        ..Default::default()
    };
    let run = track(seed, cfg, OnlineOptions::default(), 100, 300.0);
    let worst = run.worst_z.iter().map(|w| w.1).fold(0.0, f64::max);
    eprintln!(
        "worst tracked parameter: {worst:.2}σ; steps {:?}",
        run.steps
    );
    for (end, online, frozen) in &run.windows {
        eprintln!(
            "to {end:6.0} s: TCP RMS online {:6.1} µm, frozen {:6.1} µm",
            online * 1e3,
            frozen * 1e3
        );
    }
    assert!(worst < 3.0);
    assert_eq!(run.steps.len(), 1);
    assert!(run.steps[0].0 - 2400.0 <= 10.0);
}
