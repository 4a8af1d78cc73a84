//! Benchmark of the diagnosis (plain `main`, `harness = false`): a twin campaign of about
//! 1,000 poses (laser tracker, grid encoder and self-calibration, three times over) with 100
//! held-out poses and every library effect tried, the same campaign `rpkm bench calibration`
//! diagnoses; ms per diagnosis, the median of several runs, on one thread and on every core.
//!
//! cargo bench -p rpkm-core --bench diagnose [-- RUNS]

use rpkm_core::campaign::Instrument;
use rpkm_core::diagnose::{self, DiagnosisOptions};
use rpkm_core::units::um_from_mm;
use rpkm_twin::{Twin, TwinConfig};
use std::time::Instant;

fn main() {
    let runs: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(5);
    let mut twin = Twin::new(TwinConfig {
        seed: 1,
        ..Default::default()
    })
    .expect("twin");
    let three = [Instrument::Lt, Instrument::Kgm, Instrument::SelfCal];
    let cal = twin.campaign(&three.repeat(3)).expect("campaign");
    let val = twin.validation(100).expect("validation");
    for threads in [1, 0] {
        let opts = DiagnosisOptions {
            threads,
            ..Default::default()
        };
        let mut ms = Vec::new();
        let mut verdict = String::new();
        for _ in 0..runs {
            let t0 = Instant::now();
            let d = diagnose::diagnose(&cal, Some(&val), &[], &opts).expect("diagnosis");
            ms.push(t0.elapsed().as_secs_f64() * 1e3);
            verdict = format!(
                "{:?}, {} candidates, held-out {:.2} um",
                d.verdict_kind,
                d.candidates.len(),
                d.baseline.val_rms.map_or(f64::NAN, um_from_mm)
            );
        }
        ms.sort_by(f64::total_cmp);
        println!(
            "diagnosis, {} poses, threads {}: median {:.1} ms, min {:.1} ms ({verdict})",
            cal.poses.len(),
            if threads == 0 {
                "all".into()
            } else {
                threads.to_string()
            },
            ms[ms.len() / 2],
            ms[0]
        );
    }
}
