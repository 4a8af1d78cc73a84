//! Issue 37's drift check: a twin whose tracker creeps 1 µm/min along y after each zero,
//! four tracker setups each ending with a return to its reset pose. The drift each return
//! reports (`rpkm_core::returns`, with the calibrated model) is within 3σ of the twin's
//! truth (its rate times the time since the setup's zero), the long setups' drift is called
//! more than the noise, and the same campaign from a tracker that does not drift calls none.

use rand::{rngs::StdRng, Rng, SeedableRng};
use rpkm_core::calib::{self, Noise, Options, Prior, Request, Selection};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::design::{self, PlannedPose, X_RANGE, Y_RANGE};
use rpkm_core::effects::Corrections;
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{Model, Params};
use rpkm_core::returns::{drift_checks, ReturnDrift};
use rpkm_twin::{Twin, TwinConfig, ZeroDrift};

/// 1 µm/min along y, mm/s.
const RATE: f64 = 1e-3 / 60.0;

/// Self-calibration, then four tracker setups of `points[k]` random points each, reset at a
/// random pose and ending with a return there.
fn design(points: [usize; 4]) -> Vec<PlannedPose> {
    let mut rng = StdRng::seed_from_u64(5);
    let mut anywhere = || {
        (
            rng.gen_range(X_RANGE.0..=X_RANGE.1),
            rng.gen_range(Y_RANGE.0..=Y_RANGE.1),
        )
    };
    let mut d = design::self_cal();
    for (k, &n) in points.iter().enumerate() {
        let id = format!("lt{}", k + 1);
        let reset = anywhere();
        d.push(PlannedPose::new(&id, Instrument::Lt, true, reset));
        for _ in 0..n {
            d.push(PlannedPose::new(&id, Instrument::Lt, false, anywhere()));
        }
        d.push(PlannedPose::new(&id, Instrument::Lt, false, reset));
    }
    d
}

fn checks(drift: Option<ZeroDrift>) -> (Campaign, Vec<ReturnDrift>) {
    // a tracker good to 1 µm per coordinate: the drift of minutes shows against it
    let noise = NoiseModel::parse("lt=0.001").expect("noise");
    let mut twin = Twin::new(TwinConfig {
        seed: 8,
        noise: Some(noise.clone()),
        drift,
        ..TwinConfig::default()
    })
    .expect("a twin");
    let c = twin
        .run(&design([20, 60, 120, 220]), "drift")
        .expect("measured");
    let opts = Options {
        model: Model::M29,
        selection: Selection::Prior(Prior::default()),
        noise: noise.clone(),
        ..Default::default()
    };
    let start = Params::nominal();
    let (cal, _) = calib::calibrate(&Request {
        noise: Noise::ESTIMATE,
        ..Request::new(&c, &start, &opts)
    })
    .expect("calibrated");
    // judged against the stated noise, as `rpkm calibrate` does: the estimate's tracker
    // group takes the drift in and would hide it
    let d = drift_checks(
        &c,
        (&cal.params, cal.model),
        &Corrections::default(),
        &noise,
    )
    .expect("drift checks");
    (c, d)
}

#[test]
fn each_setup_reports_its_drift_within_three_sigma() {
    let (c, found) = checks(Some(ZeroDrift {
        instrument: Instrument::Lt,
        rate_per_s: [0.0, RATE],
    }));
    assert_eq!(found.len(), 4, "one return per setup: {found:?}");
    for d in &found {
        let setup = c
            .setups()
            .into_iter()
            .find(|s| s.id == d.setup)
            .expect("setup");
        let reset = &c.poses[setup.reset.expect("a reset")];
        let truth = [0.0, RATE * d.seconds];
        assert!(
            (d.seconds - (c.poses[setup.poses[setup.poses.len() - 1]].t - reset.t)).abs() < 1e-9
        );
        for (k, comp) in d.components.iter().enumerate() {
            let off = (comp.value_mm - truth[k]) / comp.sigma_mm;
            eprintln!(
                "{} {}: {:+.2} ± {:.2} µm, truth {:+.2} µm ({off:+.1} sigma)",
                d.setup,
                comp.coordinate,
                comp.value_mm * 1e3,
                comp.sigma_mm * 1e3,
                truth[k] * 1e3
            );
            assert!(off.abs() < 3.0, "{}: {off} sigma", d.setup);
        }
        // a drift of 6 µm or more against a σ of 1.4 µm is more than the noise
        if truth[1] > 6e-3 {
            assert!(d.moved(), "{d:?}");
            let rate = d.rate_mm_per_s * 60e3;
            assert!((rate - 1.0).abs() < 0.5, "{rate} µm/min");
        }
    }
    let (_, still) = checks(None);
    assert!(still.iter().all(|d| !d.moved()), "{still:?}");
}
