//! Benchmark of the geometric models and the calibration engine (plain main, side by side):
//! ns per igm and fgm (model 24 analytic start, model 29 Newton), and ms for a calibration of
//! model 29 on a 400-pose laser-tracker + self-calibration campaign.
//!
//! cargo bench -p rpkm-core --bench geometry

#[path = "../tests/support/mod.rs"]
mod support;

use rpkm_core::calib::{self, Options, Selection};
use rpkm_core::design;
use rpkm_core::geometry;
use rpkm_core::params::{Model, Params};
use std::hint::black_box;
use std::time::Instant;

fn per_call_ns(n: usize, mut f: impl FnMut(usize)) -> f64 {
    for i in 0..n / 10 {
        f(i);
    }
    let t = Instant::now();
    for i in 0..n {
        f(i);
    }
    t.elapsed().as_nanos() as f64 / n as f64
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
    println!("{:<28} {:>10}", "operation", "ns/call");
    let mut rows = Vec::new();
    for model in [Model::M24, Model::M29] {
        let igm = per_call_ns(n, |i| {
            let (x, y) = poses[i % poses.len()];
            black_box(geometry::igm(&p, model, black_box(x), y).ok());
        });
        let fgm = per_call_ns(n, |i| {
            let q = qs[i % qs.len()];
            black_box(geometry::fgm(&p, model, black_box(q[0]), q[3]).ok());
        });
        println!("{:<28} {:>10.0}", format!("igm, {model}"), igm);
        println!("{:<28} {:>10.0}", format!("fgm (q1,q4), {model}"), fgm);
        rows.push((igm, fgm));
    }
    println!(
        "model 29 / model 24: igm {:.2}x, fgm {:.2}x",
        rows[1].0 / rows[0].0,
        rows[1].1 / rows[0].1
    );

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
        let cal = calib::calibrate(&campaign, &Params::nominal(), &opts).expect("calibration");
        identified = cal.identified.len();
    }
    let ms = t.elapsed().as_secs_f64() * 1e3 / f64::from(runs);
    println!(
        "calibration, model 29, {} poses, {identified} parameters identified: {ms:.1} ms",
        campaign.poses.len()
    );
}
