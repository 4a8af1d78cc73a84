//! Benchmark of the geometric models, the warm spring fegm and the calibration engine (plain
//! main, side by side in one run): ns per igm, fgm (every viable subsystem) and warm fegm
//! (checked, the servo-rate estimator's solve, and unchecked), for both models, with the
//! ratios fgm / igm and fegm / igm; and ms for a calibration of model 29 on a 400-pose
//! laser-tracker + self-calibration campaign.
//!
//! cargo bench -p rpkm-core --bench geometry

#[path = "../tests/support/mod.rs"]
mod support;

use rpkm_core::calib::{self, Options, Selection};
use rpkm_core::design;
use rpkm_core::elastic::{
    fegm, fegm_checked_after, fegm_from, fegm_unchecked, Limits, Stiffness, ALL_ACTIVE,
};
use rpkm_core::geometry::{self, Subsystem};
use rpkm_core::params::{Model, Params};
use std::hint::black_box;
use std::time::Instant;

/// ns per call of `f`: the 10th percentile of rounds of 500 calls (about 0.1 ms each), after
/// a warm-up. The machine is shared with other builds (load 2-9), which preempt a long
/// round many times; short rounds mostly run through, and a low percentile of them is what
/// the code costs undisturbed. Every operation is measured the same way, so the ratios hold.
fn per_call_ns(n: usize, mut f: impl FnMut(usize)) -> f64 {
    const ROUND: usize = 500;
    for i in 0..n / 10 {
        f(i);
    }
    let mut rounds: Vec<f64> = (0..n / ROUND)
        .map(|r| {
            let t = Instant::now();
            for i in r * ROUND..(r + 1) * ROUND {
                f(i);
            }
            t.elapsed().as_nanos() as f64 / ROUND as f64
        })
        .collect();
    rounds.sort_by(f64::total_cmp);
    rounds[rounds.len() / 10]
}

/// ns per warm spring fegm (from the previous sample, the servo-rate use): checked with the
/// rigid reference from γ2 (`fegm_from`), checked with it from the previous rigid ψ
/// (`fegm_checked_after`), and unchecked; on a slow circle through the workspace with 0.1 mm
/// incompatibility on q3.
fn fegm_ns(p: &Params, n: usize) -> [f64; 3] {
    let k = Stiffness::default();
    let m = 2000;
    let qs: Vec<[f64; 4]> = (0..m)
        .map(|i| {
            let a = f64::from(i) / f64::from(m) * std::f64::consts::TAU;
            let (x, y) = (100.0 * a.cos(), 1700.0 + 100.0 * a.sin());
            let q = geometry::igm(p, Model::M29, x, y).expect("igm").q();
            [q[0], q[1], q[2] + 0.1, q[3]]
        })
        .collect();
    let mut prev = fegm(p, &k, qs[0], ALL_ACTIVE).expect("fegm");
    let checked = per_call_ns(n, |i| {
        prev = fegm_from(p, &k, black_box(qs[i % qs.len()]), ALL_ACTIVE, &prev).expect("fegm");
    });
    let limits = Limits::default();
    let mut last = fegm_checked_after(p, &k, qs[0], ALL_ACTIVE, None, &limits).expect("fegm");
    let after = per_call_ns(n, |i| {
        let q = black_box(qs[i % qs.len()]);
        last = fegm_checked_after(p, &k, q, ALL_ACTIVE, Some(&last), &limits).expect("fegm");
    });
    let mut raw = prev;
    let unchecked = per_call_ns(n, |i| {
        let q = black_box(qs[i % qs.len()]);
        raw = fegm_unchecked(p, &k, q, ALL_ACTIVE, Some(&raw)).expect("fegm");
    });
    [checked, after, unchecked]
}

fn main() {
    let p = support::true_params(3, false);
    let poses: Vec<(f64, f64)> = (0..1000)
        .map(|i| (-150.0 + 0.3 * f64::from(i), 700.0 + 2.0 * f64::from(i)))
        .collect();
    let qs: Vec<[f64; 4]> = poses
        .iter()
        .map(|&(x, y)| geometry::igm(&p, Model::M29, x, y).expect("igm").q())
        .collect();
    let n = 200_000;
    println!("{:<36} {:>10} {:>8}", "operation", "ns/call", "/ igm");
    let mut igms = Vec::new();
    for model in [Model::M24, Model::M29] {
        // the model's own actuator positions, so that every fgm has a solution
        let qm: Vec<[f64; 4]> = match model {
            Model::M29 => qs.clone(),
            Model::M24 => poses
                .iter()
                .map(|&(x, y)| geometry::igm(&p, model, x, y).expect("igm").q())
                .collect(),
        };
        let igm = per_call_ns(n, |i| {
            let (x, y) = poses[i % poses.len()];
            black_box(geometry::igm(&p, model, black_box(x), y).ok());
        });
        println!("{:<36} {:>10.0} {:>8.2}", format!("igm, {model}"), igm, 1.0);
        for sub in Subsystem::VIABLE {
            let Subsystem::Actuators(a, b) = sub else {
                continue;
            };
            let fgm = per_call_ns(n, |i| {
                let q = qm[i % qm.len()];
                black_box(geometry::solve(&p, model, sub, [black_box(q[a]), q[b]]).ok());
            });
            let label = format!("fgm {sub}, {model}");
            println!("{label:<36} {fgm:>10.0} {:>8.2}", fgm / igm);
        }
        igms.push(igm);
    }
    let [checked, after, unchecked] = fegm_ns(&p, n / 4);
    for (label, ns) in [
        ("fegm warm, checked, rigid from γ2", checked),
        ("fegm warm, checked, rigid warm", after),
        ("fegm warm, unchecked", unchecked),
    ] {
        println!(
            "{label:<36} {ns:>10.0} {:>8.2}  (/ igm model 24: {:.2})",
            ns / igms[1],
            ns / igms[0]
        );
    }
    println!("model 29 / model 24: igm {:.2}x", igms[1] / igms[0]);

    let plan: Vec<_> = [design::validation(250, 5), design::self_cal()].concat();
    let plan = &plan[..plan.len().min(400)];
    let campaign = support::measure(plan, &p, 9, true, "bench");
    let opts = Options {
        model: Model::M29,
        selection: Selection::Auto { max_condition: 1e6 },
        ..Default::default()
    };
    let runs = 5;
    let t = Instant::now();
    let mut identified = 0;
    for _ in 0..runs {
        let cal = calib::calibrate(&calib::Request::new(&campaign, &Params::nominal(), &opts))
            .map(|(cal, _)| cal)
            .expect("calibration");
        identified = cal.identified.len();
    }
    let ms = t.elapsed().as_secs_f64() * 1e3 / f64::from(runs);
    println!(
        "calibration, model 29, {} poses, {identified} parameters identified: {ms:.1} ms",
        campaign.poses.len()
    );
}
