//! What the online tracker reports (issue 15), on the twin's production stream against its
//! truth: a crash named by rod (alone where the path separates the rods, "this or that"
//! where the forces move alike for both), and silence on a machine that does not drift
//! (no drift WARN, no step).
//!
//! The tracker starts from the twin's true machine at the start with the tolerance prior's
//! σ (what it knows without a calibration) and reads the stream at 10 Hz (5 Hz for the
//! drift: six minutes).
use rpkm_core::calib::online::{
    DriftMonitor, ForceSample, OnlineEstimator, OnlineOptions, Outcome, StepChange as Step,
};
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{index_of, NAMES, N_PARAMS};
use rpkm_core::twin::{
    EffectKind, ProductionConfig, ProductionStream, StepChange, ThermalPhysics, Twin, TwinConfig,
};

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

/// What the tracker said over a stream.
struct Told {
    steps: Vec<(f64, Step)>,
    /// Drift warnings at each check: time, the monitor's message, the parameters named.
    drifts: Vec<(f64, String, Vec<usize>)>,
}

/// The tracker over `cfg`'s stream; the drift monitor as the calibrator node runs it (a point
/// every 10 updates, checked at each point against `warn_mm`).
fn run(seed: u64, cfg: ProductionConfig, opts: OnlineOptions, warn_mm: f64) -> Told {
    let t = twin(seed);
    let mut stream = ProductionStream::new(&t, cfg).peekable();
    let start = stream
        .peek()
        .and_then(|s| s.as_ref().ok())
        .expect("first sample")
        .truth;
    let mut est = OnlineEstimator::from_sigmas(start, None, opts);
    let mut monitor = DriftMonitor::new(4096);
    let mut told = Told {
        steps: Vec::new(),
        drifts: Vec::new(),
    };
    for (n, s) in stream.enumerate() {
        let s = s.expect("production sample");
        let out = est
            .update(&ForceSample {
                t: s.t,
                q: s.q,
                f: s.f,
            })
            .expect("update");
        if let Outcome::Step(step) = out {
            told.steps.push((s.t, step));
            monitor.rebase();
        }
        if n % 10 == 0 {
            monitor.record(s.t, s.temp_c, est.params());
            let sigma: [f64; N_PARAMS] = std::array::from_fn(|i| est.sigma(i));
            let d = monitor.drifts(warn_mm, &sigma);
            if !d.is_empty() {
                let text = d
                    .iter()
                    .map(|d| d.describe("temp_machine"))
                    .collect::<Vec<_>>()
                    .join("; ");
                told.drifts
                    .push((s.t, text, d.iter().map(|d| d.param).collect()));
            }
        }
    }
    told
}

fn crash(seed: u64, rod: &str) -> (f64, Step) {
    let param = index_of(rod).expect("rod");
    let cfg = ProductionConfig {
        rate_hz: 10.0,
        seconds: 32.0,
        step: Some(StepChange {
            at_s: 20.0,
            param,
            change: 0.1,
        }),
        seed,
        ..Default::default()
    };
    let told = run(seed, cfg, OnlineOptions::default(), 0.01);
    assert_eq!(told.steps.len(), 1, "steps: {:?}", told.steps);
    let (named_at, step) = told.steps[0];
    eprintln!(
        "seed {seed}, crash {rod}: named {}{} {:+.4} mm, margin {:.4}, {:.1} s after",
        NAMES[step.param],
        step.alternative
            .map_or(String::new(), |a| format!(" or {}", NAMES[a])),
        step.change,
        step.margin,
        named_at - 20.0
    );
    assert!(named_at - 20.0 <= 10.0, "named at {named_at} s");
    assert!(
        (20.0..20.2).contains(&step.since_s),
        "seen at {}",
        step.since_s
    );
    assert!((step.change - 0.1).abs() < 0.02, "size {} mm", step.change);
    (named_at, step)
}

#[test]
fn a_crash_of_rod_4_is_named_alone() {
    let (_, step) = crash(7, "l4");
    assert_eq!(NAMES[step.param], "l4", "{step:?}");
    assert_eq!(step.alternative, None, "the path separates rod 4: {step:?}");
    assert!(step.margin >= OnlineOptions::default().step_margin);
}

#[test]
fn a_crash_of_rod_3_is_named_with_rod_1_that_the_forces_cannot_tell_from_it() {
    let (_, step) = crash(41, "l3");
    let named = [Some(step.param), step.alternative];
    assert!(
        named.contains(&index_of("l3")) && named.contains(&index_of("l1")),
        "l3 or l1: {step:?}"
    );
    assert!(step.margin < OnlineOptions::default().step_margin);
}

fn drift_stream(seed: u64, k_per_h: f64) -> ProductionConfig {
    ProductionConfig {
        rate_hz: 5.0,
        seconds: 360.0,
        drift_k_per_h: k_per_h,
        seed,
        ..Default::default()
    }
}

/// The random walks the 4 K in 6 minutes need (40 K/h: 3x the default rates).
fn fast_drift() -> OnlineOptions {
    OnlineOptions {
        length_drift_mm_per_sqrt_h: 0.15,
        angle_drift_rad_per_sqrt_h: 3e-4,
        ..OnlineOptions::default()
    }
}

#[test]
fn a_machine_that_does_not_drift_raises_no_drift() {
    let told = run(5, drift_stream(5, 0.0), fast_drift(), 0.01);
    assert!(told.steps.is_empty(), "steps: {:?}", told.steps);
    assert!(
        told.drifts.is_empty(),
        "drifts: {:?}",
        &told.drifts[..told.drifts.len().min(3)]
    );
}
