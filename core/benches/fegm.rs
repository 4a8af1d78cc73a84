//! Benchmark of the elasto-geometric forward model against the rigid fgm (plain `main`,
//! `harness = false`): ns per sample for
//! - rigid fgm(q1, q4) (model 29),
//! - spring fegm, cold (rigid start + Newton), all four drives active,
//! - spring fegm, warm (from the previous sample: the servo-rate use), with its plausibility
//!   checks (a rigid fgm for the reference, loop closure, balance; the default), and the raw
//!   solver without them (`fegm_unchecked`: what the checks cost),
//! - finite-element model (rigid reference + assembly + dense Cholesky), by the
//!   actuator-displacements and the thermo-mechanical method, one `FeModel` reused so that its
//!   buffers are allocated once;
//!
//! on a slow trajectory through the workspace with a 0.1 mm incompatibility on q3, and the
//! ratios to the rigid fgm and to the warm spring fegm.
//!
//! Run: `cargo bench -p rpkm-core --bench fegm` (needs `[[bench]] name = "fegm"
//! harness = false` in core/Cargo.toml), or build it as an example.

use rpkm_core::elastic::fe::{FeMethod, FeModel, FeStiffness};
use rpkm_core::elastic::{fegm, fegm_from, fegm_unchecked, Stiffness, ALL_ACTIVE};
use rpkm_core::geometry::{fgm, igm};
use rpkm_core::params::{Model, Params};
use std::hint::black_box;
use std::time::Instant;

fn main() {
    let p = Params::nominal();
    let k = Stiffness::default();
    let n = 2000;
    let qs: Vec<[f64; 4]> = (0..n)
        .map(|i| {
            let a = f64::from(i) / f64::from(n) * std::f64::consts::TAU;
            let (x, y) = (100.0 * a.cos(), 1700.0 + 100.0 * a.sin());
            let q = igm(&p, Model::M29, x, y).expect("igm").q();
            [q[0], q[1], q[2] + 0.1, q[3]]
        })
        .collect();
    let reps = 20;
    let time = |label: &str, f: &mut dyn FnMut(&[f64; 4]) -> f64| -> f64 {
        let mut acc = 0.0;
        for q in &qs {
            acc += f(q);
        }
        let t0 = Instant::now();
        for _ in 0..reps {
            for q in &qs {
                acc += f(black_box(q));
            }
        }
        let ns = t0.elapsed().as_nanos() as f64 / f64::from(reps * n);
        black_box(acc);
        println!("{label:<36} {ns:>9.0} ns/sample");
        ns
    };
    let rigid = time("rigid fgm(q1, q4), model 29", &mut |q| {
        fgm(&p, Model::M29, q[0], q[3]).expect("fgm").x()
    });
    let cold = time("spring fegm, cold start", &mut |q| {
        fegm(&p, &k, *q, ALL_ACTIVE).expect("fegm").x
    });
    let mut prev = fegm(&p, &k, qs[0], ALL_ACTIVE).expect("fegm");
    let warm = time("spring fegm, warm (previous sample)", &mut |q| {
        prev = fegm_from(&p, &k, *q, ALL_ACTIVE, &prev).expect("fegm");
        prev.x
    });
    let mut raw = prev;
    let unchecked = time("spring fegm, warm, no checks", &mut |q| {
        raw = fegm_unchecked(&p, &k, *q, ALL_ACTIVE, Some(&raw)).expect("fegm");
        raw.x
    });
    println!("plausibility checks: {:.0} ns/sample", warm - unchecked);
    let mut model = FeModel::new(FeStiffness::default()).expect("FE stiffness");
    let fe_ad = time("FE model, actuator-displacements", &mut |q| {
        model
            .solve(&p, *q, ALL_ACTIVE, FeMethod::ActuatorDisplacements)
            .expect("fe")
            .x
    });
    let fe_th = time("FE model, thermo-mechanical", &mut |q| {
        model
            .solve(&p, *q, ALL_ACTIVE, FeMethod::ThermoMechanical)
            .expect("fe")
            .x
    });
    println!(
        "ratio cold / rigid {:.2}, warm / rigid {:.2}",
        cold / rigid,
        warm / rigid
    );
    println!(
        "ratio FE actuator-displacements / rigid {:.1}, / spring warm {:.1}; FE thermo-mechanical / rigid {:.1}, / spring warm {:.1}",
        fe_ad / rigid,
        fe_ad / warm,
        fe_th / rigid,
        fe_th / warm
    );
}
