//! Benchmark of the online tracker's cost per sample (plain `main`, `harness = false`), on
//! the twin's production stream at 10 Hz (seed 5, a crash of l3 by 0.1 mm at 60 s, which the
//! path ties with l1 and leaves open), the tracker starting from the tolerances:
//! - an update before the crash (one estimate),
//! - an update while the tie is open (two estimates predict and take each sample),
//! - the update that names the step (the step, the second estimate, the motion planned over
//!   the 231-pose grid),
//!
//! each the median over the stream's samples of that kind, and the ratio of the tie's
//! updates to the plain ones, measured side by side in one run.
//!
//! Run: `cargo bench -p rpkm-core --bench online`.

use rpkm_core::online::{ForceSample, OnlineEstimator, OnlineOptions, UpdateOutcome};
use rpkm_core::params::index_of;
use rpkm_twin::{ProductionConfig, ProductionStream, StepChange};

// the online tests' twin, the same file
#[path = "../tests/it/support/production.rs"]
mod production;
use std::time::Instant;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() {
    let twin = production::twin(5);
    let cfg = ProductionConfig {
        rate_hz: 10.0,
        seconds: 180.0,
        step: Some(StepChange {
            at_s: 60.0,
            param: index_of("l3").expect("l3"),
            change: 0.1,
        }),
        seed: 5,
        ..Default::default()
    };
    let samples: Vec<ForceSample> = ProductionStream::new(&twin, cfg)
        .map(|s| {
            let s = s.expect("sample");
            ForceSample {
                t: s.t,
                q: s.q,
                f: s.f,
            }
        })
        .collect();
    let mut est = OnlineEstimator::from_sigmas(*twin.true_params(), None, OnlineOptions::default());
    let (mut plain, mut tied, mut named) = (Vec::new(), Vec::new(), None);
    for s in &samples {
        let open = est.tie().is_some();
        let t0 = Instant::now();
        let out = est.update(s).expect("update");
        let us = t0.elapsed().as_secs_f64() * 1e6;
        match out {
            UpdateOutcome::Step(step) => {
                named = Some((us, step.separating.map_or(0, |m| m.poses.len())));
            }
            _ if open => tied.push(us),
            _ if s.t < 60.0 => plain.push(us),
            _ => {}
        }
    }
    let (p, t) = (median(&mut plain), median(&mut tied));
    println!(
        "update, one estimate (before the crash) {p:>9.1} µs/sample ({} samples)",
        plain.len()
    );
    println!(
        "update, a tie open (two estimates)     {t:>9.1} µs/sample ({} samples)",
        tied.len()
    );
    if let Some((us, poses)) = named {
        println!(
            "the update that names the step          {:>9.1} ms (the motion: {poses} poses)",
            us / 1e3
        );
    }
    println!("ratio, a tie open / one estimate        {:>9.2}x", t / p);
    if let Some(tie) = est.tie() {
        println!(
            "(the tie still open at the end, evidence χ² {:.1})",
            tie.evidence.chi2
        );
    }
}
