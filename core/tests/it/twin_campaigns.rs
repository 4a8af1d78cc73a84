//! The digital twin: campaign structure, consistency of effect-free data with the true
//! parameters, and the footprint of each hidden effect.

use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::design::PlannedPose;
use rpkm_core::geometry::{fgm, rgm};
use rpkm_core::params::Model;
use rpkm_twin::{EffectKind, Twin, TwinConfig, TwinError};

fn twin(seed: u64, effects: Vec<(EffectKind, f64)>, noise: bool) -> Twin {
    Twin::new(TwinConfig {
        seed,
        effects,
        noise: noise.then(rpkm_core::noise::NoiseModel::default),
        ..TwinConfig::default()
    })
    .expect("twin")
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

#[test]
fn campaigns_have_the_structure_of_the_spec() {
    let mut t = twin(3, vec![], true);
    let expect: [(Instrument, usize, usize); 8] = [
        (Instrument::Lt, 1, 45),
        (Instrument::Kgm, 16, 16 * 9),
        (Instrument::Dbb, 8, 8 * 38),
        (Instrument::LiX, 9, 9 * 21),
        (Instrument::LiY, 13, 13 * 81),
        (Instrument::LiPsi, 4, 28 + 3 * 21),
        (Instrument::SelfCal, 4, 149),
        (Instrument::Circle, 1, 74),
    ];
    let mut last_t = 0.0;
    for (inst, setups, poses) in expect {
        let c = t.campaign(&[inst]).expect("campaign");
        c.validate().expect("valid campaign");
        assert_eq!(c.setups().len(), setups, "{inst}");
        assert_eq!(c.poses.len(), poses, "{inst}");
        for s in c.setups() {
            let resets = s.poses.iter().filter(|&&i| c.poses[i].reset).count();
            let want = usize::from(inst.takes_reset());
            assert_eq!(resets, want, "{inst} setup {}", s.id);
        }
        assert!(c.poses[0].t > last_t, "the clock runs on across campaigns");
        last_t = c.poses.last().expect("poses").t;
        let self_cal = inst == Instrument::SelfCal;
        for p in &c.poses {
            assert_eq!(p.follower, [false, true, true, false]);
            assert!(p.f.iter().all(|f| *f == 0.0));
            if self_cal {
                assert!(p.x.is_none() && p.y.is_none());
            }
        }
        // Round trip through the CSV format.
        let back = Campaign::parse(&c.to_csv(), "twin.csv").expect("parse");
        assert_eq!(back.poses.len(), c.poses.len());
        assert_eq!(back.covariate_names, vec!["temp_machine".to_owned()]);
    }
    let v = t.validation(40).expect("validation");
    v.validate().expect("valid");
    assert_eq!(v.poses.len(), 41);
    assert_eq!(v.setups().len(), 1);
}

/// Residuals of a campaign against the rigid model of `truth`: relative x, y, r, psi per pose
/// (inverse check: the TCP from fgm of the recorded q1, q4) and the follower encoders.
fn residuals(c: &Campaign, truth: &rpkm_core::params::Params) -> (Vec<f64>, Vec<f64>) {
    let mut pos = Vec::new();
    let mut fol = Vec::new();
    for s in c.setups() {
        let reset = s.reset.map(|i| {
            let p = &c.poses[i];
            fgm(truth, Model::M29, p.q[0], p.q[3]).expect("fgm")
        });
        for &i in &s.poses {
            let p = &c.poses[i];
            let sol = fgm(truth, Model::M29, p.q[0], p.q[3]).expect("fgm");
            let [q2, q3] = rgm(truth, Model::M29, p.q[0], p.q[3]).expect("rgm");
            fol.push(p.q[1] - q2);
            fol.push(p.q[2] - q3);
            let Some(r) = &reset else { continue };
            if p.reset {
                continue;
            }
            let (dx, dy) = (sol.x() - r.x(), sol.y() - r.y());
            if let Some(x) = p.x {
                pos.push(x - dx);
            }
            if let Some(y) = p.y {
                pos.push(y - dy);
            }
            if let Some(m) = p.r {
                pos.push(m - dx.hypot(dy));
            }
            if let Some(psi) = p.psi {
                pos.push((psi - (sol.psi() - r.psi())) * 1e3);
            }
        }
    }
    (pos, fol)
}

#[test]
fn effect_free_data_is_reproduced_by_the_true_parameters() {
    // Without noise: exact.
    let mut t = twin(5, vec![], false);
    let truth = *t.true_params();
    for inst in [
        Instrument::Lt,
        Instrument::Kgm,
        Instrument::Dbb,
        Instrument::SelfCal,
    ] {
        let c = t.campaign(&[inst]).expect("c");
        let (pos, fol) = residuals(&c, &truth);
        assert!(pos.iter().all(|r| r.abs() < 1e-8), "{inst}: {pos:?}");
        assert!(fol.iter().all(|r| r.abs() < 1e-8), "{inst}");
    }
    // With noise: RMS consistent with the instrument sigma.
    let mut t = twin(5, vec![], true);
    for (inst, lo, hi) in [
        (Instrument::Lt, 0.004, 0.040),
        (Instrument::Kgm, 0.0005, 0.003),
        (Instrument::LiY, 0.0005, 0.003),
        (Instrument::Dbb, 0.0005, 0.003),
    ] {
        let c = t.campaign(&[inst]).expect("c");
        let (pos, fol) = residuals(&c, &truth);
        let r = rms(&pos);
        eprintln!("{inst}: residual RMS {:.2} µm", r * 1e3);
        assert!(r > lo && r < hi, "{inst}: {r}");
        assert!(
            rms(&fol) < 3.0 * rpkm_core::noise::NoiseModel::default().encoder_mm,
            "{inst}"
        );
    }
}

fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

#[test]
fn thermal_residual_correlates_with_temp_machine() {
    let mut t = twin(7, vec![(EffectKind::Thermal, 2.0)], true);
    let truth = *t.true_params();
    // The self-calibration campaign, then the centre pose held in follower mode for 40 min:
    // the drift of q2, q3 there is thermal alone.
    let _ = t.campaign(&[Instrument::SelfCal]).expect("self");
    let hold: Vec<PlannedPose> = (0..800)
        .map(|_| PlannedPose::new("hold", Instrument::SelfCal, false, (0.0, 1700.0)))
        .collect();
    let c = t.run(&hold, "hold").expect("hold");
    let temp: Vec<f64> = c
        .covariate("temp_machine")
        .expect("column")
        .into_iter()
        .map(|v| v.expect("value"))
        .collect();
    let (_, fol) = residuals(&c, &truth);
    let q3: Vec<f64> = fol.iter().skip(1).step_by(2).copied().collect();
    let corr = correlation(&q3, &temp);
    eprintln!(
        "thermal: corr(q3 residual, temp_machine) = {corr:.3}, temp range {:.2}..{:.2} °C",
        temp.iter().copied().fold(f64::INFINITY, f64::min),
        temp.iter().copied().fold(f64::NEG_INFINITY, f64::max)
    );
    assert!(corr.abs() > 0.95, "{corr}");
}

/// Same seed with and without an effect: the noise draws are the same, so the difference is
/// the effect alone.
fn diff(effect: EffectKind, inst: Instrument) -> f64 {
    let a = twin(11, vec![], true).campaign(&[inst]).expect("a");
    let b = twin(11, vec![(effect, effect.default_magnitude())], true)
        .campaign(&[inst])
        .expect("b");
    let mut d = Vec::new();
    for (p, q) in a.poses.iter().zip(&b.poses) {
        for (u, v) in [(p.x, q.x), (p.y, q.y), (p.r, q.r)] {
            if let (Some(u), Some(v)) = (u, v) {
                d.push(u - v);
            }
        }
        if let (Some(u), Some(v)) = (p.psi, q.psi) {
            d.push((u - v) * 1e3);
        }
        if inst == Instrument::SelfCal {
            d.push(p.q[1] - q.q[1]);
            d.push(p.q[2] - q.q[2]);
        }
    }
    rms(&d)
}

#[test]
fn each_effect_changes_the_measurements_it_touches() {
    use EffectKind::*;
    for (e, inst, min) in [
        (Parallelogram, Instrument::LiPsi, 0.005),
        (Parallelogram, Instrument::Lt, 0.005),
        (PreloadElastic, Instrument::Lt, 0.005),
        (Thermal, Instrument::Lt, 0.005),
        (EncoderScale, Instrument::LiY, 0.005),
        (GuideStraightness, Instrument::Lt, 0.005),
        (InstrumentAlignment, Instrument::Lt, 0.005),
    ] {
        let d = diff(e, inst);
        eprintln!("{e} on {inst}: RMS change {:.1} µm", d * 1e3);
        assert!(d > min, "{e} on {inst}: {d}");
    }
    // Instrument alignment cannot change distances or angles.
    assert!(diff(InstrumentAlignment, Instrument::Dbb) < 1e-12);
    assert!(diff(InstrumentAlignment, Instrument::LiPsi) < 1e-12);
    // Self-calibration switches q2, q3 to followers: no preload there.
    assert!(diff(PreloadElastic, Instrument::SelfCal) < 1e-12);
}

#[test]
fn preload_elastic_records_drive_forces() {
    let mut t = twin(13, vec![(EffectKind::PreloadElastic, 1.0)], true);
    let c = t.campaign(&[Instrument::Lt]).expect("c");
    let max = c
        .poses
        .iter()
        .flat_map(|p| p.f)
        .fold(0.0f64, |m, f| m.max(f.abs()));
    eprintln!("preload_elastic: largest drive force {max:.0} N");
    assert!(c.poses.iter().all(|p| p.follower == [false; 4]));
    assert!(max > 100.0);
}

#[test]
fn deterministic_and_typed_errors() {
    let a = twin(17, vec![(EffectKind::Thermal, 1.0)], true)
        .campaign(&[Instrument::Kgm])
        .expect("a");
    let b = twin(17, vec![(EffectKind::Thermal, 1.0)], true)
        .campaign(&[Instrument::Kgm])
        .expect("b");
    assert_eq!(a, b);
    let dup = Twin::new(TwinConfig {
        effects: vec![(EffectKind::Thermal, 1.0), (EffectKind::Thermal, 2.0)],
        ..TwinConfig::default()
    });
    assert!(matches!(dup, Err(TwinError::DuplicateEffect(_))));
    let mut t = twin(1, vec![], true);
    assert!(matches!(
        t.campaign_by_names(&["bogus"], 10),
        Err(TwinError::UnknownCampaign(_))
    ));
    let truth = t.truth();
    let json = serde_json::to_string(&truth).expect("json");
    let back: rpkm_twin::Truth = serde_json::from_str(&json).expect("back");
    assert_eq!(back, truth);
}

/// A campaign measured twice is two mountings: every setup of the second run is new
/// (`lt_2`), with its own reset, so the written file reads back under the spec's rule of one
/// reset per setup.
#[test]
fn a_repeated_campaign_reads_back_as_new_setups() {
    let mut t = twin(4, vec![], true);
    let c = t
        .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::Lt])
        .expect("campaign");
    let back = Campaign::parse(&c.to_csv(), "repeated.csv").expect("the spec's reader takes it");
    assert_eq!(back.poses.len(), c.poses.len());
    let setups = back.setups();
    let lt: Vec<_> = setups
        .iter()
        .filter(|s| s.instrument == Instrument::Lt)
        .collect();
    assert_eq!(lt.len(), 2);
    assert!(lt.iter().all(|s| s.reset.is_some()));
    assert_ne!(lt[0].id, lt[1].id);
    assert_eq!(setups.len(), 2 + 16);
}

/// A tracker creeping 1 µm/min along y after its zero: on a noiseless twin each reading is
/// the drift-free reading plus 1 µm/min times the time since its setup's reset pose (read
/// off the campaign's `t`), the grid encoder measured beside it does not drift, and the
/// truth names the drift.
#[test]
fn a_drifting_instrument_reads_its_rate_times_the_time_since_its_zero() {
    let rate = 1e-3 / 60.0;
    let measure = |drift: Option<rpkm_twin::ZeroDrift>| {
        let mut t = Twin::new(TwinConfig {
            seed: 4,
            noise: None,
            drift,
            ..TwinConfig::default()
        })
        .expect("twin");
        let c = t
            .campaign(&[Instrument::Lt, Instrument::Kgm])
            .expect("lt, kgm");
        (c, t.truth())
    };
    let drift = rpkm_twin::ZeroDrift {
        instrument: Instrument::Lt,
        rate_per_s: [0.0, rate],
    };
    let (still, _) = measure(None);
    let (moving, truth) = measure(Some(drift));
    assert_eq!(truth.drift, Some(drift));
    let zero_t = moving.poses[0].t;
    let mut largest: f64 = 0.0;
    for (a, b) in still.poses.iter().zip(&moving.poses) {
        let (Some(ya), Some(yb), Some(xa), Some(xb)) = (a.y, b.y, a.x, b.x) else {
            continue;
        };
        let want = if b.instrument == Instrument::Lt {
            rate * (b.t - zero_t)
        } else {
            0.0
        };
        assert!(
            (yb - ya - want).abs() < 1e-12,
            "line {}: {} {}",
            b.line,
            yb - ya,
            want
        );
        assert!((xb - xa).abs() < 1e-12, "line {}: x does not drift", b.line);
        largest = largest.max(yb - ya);
    }
    assert!(largest > 1e-3, "the setup lasts minutes: {largest} mm");
    let bad = Twin::new(TwinConfig {
        drift: Some(rpkm_twin::ZeroDrift {
            instrument: Instrument::SelfCal,
            rate_per_s: [0.0, rate],
        }),
        ..TwinConfig::default()
    });
    assert!(matches!(bad, Err(TwinError::BadDrift { .. })), "{bad:?}");
}
