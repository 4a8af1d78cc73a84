//! Effects written as data (`effects::Written`): their parameter derivatives against finite
//! differences, the library's `encoder_scale` written as expressions giving the library's
//! parameters, and a twin with lost motion of carrier 4 (its own implementation, not the
//! expression's) found and fitted by `dq4 = -b * dir_q4`. The truth is the twin's.

use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::diagnose::{self, DiagnosisOptions, ModelDiagnosis, VerdictKind};
use rpkm_core::effects::written::{Spec, WrittenParam};
use rpkm_core::effects::{Delta, Effect, EncoderScale, Written};
use rpkm_core::params::Params;
use rpkm_core::units::um_from_mm;
use rpkm_twin::{EffectKind, Twin, TwinConfig};

fn param(name: &str, unit: &str, prior: f64) -> WrittenParam {
    WrittenParam {
        name: name.into(),
        unit: unit.into(),
        prior,
        bounds: None,
        start: 0.0,
    }
}

fn written(name: &str, params: Vec<WrittenParam>, targets: &[(&str, &str)]) -> Written {
    let spec = Spec {
        name: name.into(),
        summary: "test".into(),
        params,
        targets: targets
            .iter()
            .map(|(t, e)| ((*t).to_owned(), (*e).to_owned()))
            .collect(),
        instruments: None,
    };
    Written::new(spec, &[]).expect("a valid effect")
}

/// Calibration campaign (laser tracker, grid encoder, self-calibration), 100 held-out tracker
/// poses, and the held-out noise floor (the same twin measured without noise).
fn twin_campaigns(seed: u64, hidden: &[(EffectKind, f64)]) -> (Campaign, Campaign, f64) {
    let config = TwinConfig {
        seed,
        effects: hidden.to_vec(),
        noise: Some(rpkm_core::noise::NoiseModel::default()),
        ..Default::default()
    };
    let measure = |config: TwinConfig| {
        let mut twin = Twin::new(config).expect("twin");
        let cal = twin
            .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])
            .expect("campaign");
        (cal, twin.validation(100).expect("validation"))
    };
    let (cal, val) = measure(config.clone());
    let (_, clean) = measure(TwinConfig {
        noise: None,
        ..config
    });
    let floor = rpkm_twin::reading_error_rms_um(&val, &clean);
    (cal, val, floor)
}

fn apply(e: &Written, campaign: &Campaign, pose: usize, theta: &[f64]) -> (Delta, Vec<Delta>) {
    let bound = e.bind(campaign, &Params::nominal()).expect("binds");
    let mut value = Delta::default();
    let mut partials = vec![Delta::default(); theta.len()];
    bound.correct(pose, theta, &mut value, &mut partials);
    (value, partials)
}

/// Every target kind, with covariates, derived covariates, forces and the TCP: each partial
/// against a central difference of the value.
#[test]
fn partials_match_finite_differences() {
    let (cal, _, _) = twin_campaigns(3, &[]);
    let e = written(
        "mixed",
        vec![
            param("a", "mm", 0.01),
            param("c", "mm", 0.01),
            param("k", "1", 0.1),
        ],
        &[
            (
                "dq4",
                "a * sin(2*pi*q4/60) + c * cos(2*pi*q4/60) - k^2 * dir_q4",
            ),
            ("dx", "a * y / 1000 + exp(k) * c"),
            (
                "dp.l3",
                "(a + c*k) * (temp_machine - 20) + tanh(k * t_run / 100)",
            ),
            (
                "dq1",
                "abs(a - c) * f1 / 1000 + max(a, k) * travel_q1 / 1e4",
            ),
        ],
    );
    let theta = [0.004, -0.003, 0.2];
    for pose in [1, 17, cal.poses.len() - 1] {
        let (_, partials) = apply(&e, &cal, pose, &theta);
        for k in 0..3 {
            let h = 1e-6;
            let (mut up, mut down) = (theta, theta);
            up[k] += h;
            down[k] -= h;
            let (vu, vd) = (apply(&e, &cal, pose, &up).0, apply(&e, &cal, pose, &down).0);
            let fd = |u: f64, d: f64| (u - d) / (2.0 * h);
            let pairs = [
                (partials[k].dq[3], fd(vu.dq[3], vd.dq[3])),
                (partials[k].dq[0], fd(vu.dq[0], vd.dq[0])),
                (partials[k].dm.x, fd(vu.dm.x, vd.dm.x)),
                (
                    partials[k].dp[rpkm_core::params::L3],
                    fd(vu.dp[rpkm_core::params::L3], vd.dp[rpkm_core::params::L3]),
                ),
            ];
            for (exact, numeric) in pairs {
                assert!(
                    (exact - numeric).abs() <= 1e-6 * (1.0 + numeric.abs()),
                    "pose {pose} θ{k}: exact {exact}, finite difference {numeric}"
                );
            }
        }
    }
}

/// `dpsi` (true minus recorded platform angle) beside `dx`, on the angle interferometer's and
/// the 2-D instruments' rows: every row's parameter Jacobian against a central difference of
/// its value, and the angle rows' against the derivative by hand (the recorded angle enters
/// each angle row with −1: ∂/∂a = −(1 + q1/1000)).
#[test]
fn dpsi_rows_match_finite_differences() {
    use rpkm_core::effects::EffectSet;
    use rpkm_core::noise::NoiseModel;
    use rpkm_core::obs::{self, Form, Step};
    use rpkm_core::params::Model;
    let mut twin = Twin::new(TwinConfig {
        seed: 4,
        noise: Some(NoiseModel::default()),
        ..Default::default()
    })
    .expect("twin");
    let c = twin
        .campaign(&[Instrument::LiPsi, Instrument::LiX, Instrument::Lt])
        .expect("campaign");
    let e = written(
        "angle",
        vec![param("a", "rad", 1e-5), param("c", "mm", 0.01)],
        &[
            ("dpsi", "a * (1 + q1 / 1000) + c^2 * 1e-3"),
            ("dx", "c * sin(q4 / 100)"),
        ],
    );
    let p = Params::nominal();
    let set = EffectSet::bind(&[&e], &c, &p).expect("binds");
    let rows = |theta: &[f64]| {
        obs::residuals_in(
            &c,
            &p,
            Model::M29,
            Step::Direct,
            &p,
            &set.corrections(theta, &p),
            &NoiseModel::default(),
            Form::Thesis,
        )
        .expect("rows")
    };
    let theta = [3e-5, 0.02];
    let at = rows(&theta);
    for (k, prior) in [1e-5, 0.01].into_iter().enumerate() {
        let h = 1e-3 * prior;
        let (mut up, mut down) = (theta, theta);
        up[k] += h;
        down[k] -= h;
        let (ru, rd) = (rows(&up), rows(&down));
        for (i, r) in at.iter().enumerate() {
            let fd = (ru[i].value - rd[i].value) / (2.0 * h);
            assert!(
                (fd - r.d_theta[k]).abs() <= 1e-6 * r.d_theta[k].abs().max(1.0),
                "θ{k} row {i} ({} {}): exact {}, finite difference {fd}",
                r.instrument,
                r.direction,
                r.d_theta[k]
            );
        }
    }
    let angle: Vec<_> = at.iter().filter(|r| r.direction.is_angle()).collect();
    assert!(angle.len() > 10, "{} angle rows", angle.len());
    for r in angle {
        let by_hand = -(1.0 + c.poses[r.pose].q[0] / 1000.0);
        assert!(
            (r.d_theta[0] - by_hand).abs() < 1e-12,
            "pose {}: {} against {by_hand}",
            r.pose,
            r.d_theta[0]
        );
    }
}

/// The library's `encoder_scale` (ppm per guide: guide 1 carries q2, q3, guide 2 q1, q4) and
/// the same written as expressions: the same parameters, to 1e-6 relative.
#[test]
fn encoder_scale_written_gives_the_librarys_parameters() {
    let (cal, val, _) = twin_campaigns(5, &[(EffectKind::EncoderScale, 40.0)]);
    let file = written(
        "encoder_scale_written",
        vec![
            param("scale_guide1", "ppm", 50.0),
            param("scale_guide2", "ppm", 50.0),
        ],
        &[
            ("dq2", "scale_guide1 * 1e-6 * q2"),
            ("dq3", "scale_guide1 * 1e-6 * q3"),
            ("dq1", "scale_guide2 * 1e-6 * q1"),
            ("dq4", "scale_guide2 * 1e-6 * q4"),
        ],
    );
    let opts = DiagnosisOptions::default();
    let lib = diagnose::evaluate(&cal, Some(&val), &[&EncoderScale], &opts)
        .expect("library")
        .fit;
    let own = diagnose::evaluate(&cal, Some(&val), &[&file], &opts)
        .expect("written")
        .fit;
    assert_eq!(lib.effect_params.len(), 2);
    for (a, b) in lib.effect_params.iter().zip(&own.effect_params) {
        eprintln!(
            "{}: library {} ± {}, written {} ± {}",
            a.name, a.value, a.sigma, b.value, b.sigma
        );
        assert_eq!(a.name, b.name);
        assert!(
            (a.value - b.value).abs() <= 1e-6 * a.value.abs(),
            "{a:?} vs {b:?}"
        );
        assert!(
            (a.sigma - b.sigma).abs() <= 1e-6 * a.sigma.abs(),
            "{a:?} vs {b:?}"
        );
    }
    // the twin's 40 ppm of guide 2 is found (guide 1 has none)
    let g2 = &lib.effect_params[1];
    assert!((g2.value - 40.0).abs() < 3.0 * g2.sigma, "{g2:?}");
}

fn summary(d: &ModelDiagnosis) -> String {
    format!(
        "{:?}, missing {:?}, held-out {:?} um, candidates {:?}",
        d.verdict_kind,
        d.missing_effect,
        d.baseline.val_rms.map(um_from_mm),
        d.candidates
            .iter()
            .map(|c| (
                c.effect.as_str(),
                c.significant,
                c.bic_gain.round(),
                c.val_rms_after.map(um_from_mm),
                c.prediction.map(|p| (p.better, p.worse)),
                c.cross_validated.map(|p| (p.better, p.worse))
            ))
            .collect::<Vec<_>>()
    )
}

/// The twin's lost motion of carrier 4 (20 µm against the direction of its last move), on
/// three machines: the written `dq4 = -b * dir_q4` is offered and significant, b is found
/// within 3σ, and with it in the model the held-out error is at the noise floor and no
/// further effect is missing. Whether the first diagnosis names it rests on the held-out
/// judge (a better prediction pose by pose), which a noisy reset reading of the single
/// held-out setup can fool by a few µm: printed, not asserted here (docs/effects.md).
#[test]
fn lost_motion_of_carrier_4_is_found_by_a_written_effect() {
    let b_true = 0.02;
    let lost = written(
        "lost_motion_q4",
        vec![param("b", "mm", 0.01)],
        &[("dq4", "-b * dir_q4")],
    );
    let opts = DiagnosisOptions::default();
    for seed in [7, 8, 9] {
        let (cal, val, floor) = twin_campaigns(seed, &[(EffectKind::LostMotionQ4, b_true)]);
        let d = diagnose::diagnose_among(&cal, Some(&val), &[], &[&lost], &opts).expect("diagnose");
        eprintln!("seed {seed} before: {} (floor {floor:.2} um)", summary(&d));
        let c = d
            .candidates
            .iter()
            .find(|c| c.effect == "lost_motion_q4")
            .expect("candidate");
        assert!(c.significant, "seed {seed}: {}", summary(&d));
        assert_eq!(
            d.candidates[0].effect, "lost_motion_q4",
            "seed {seed}: ranked first"
        );
        let b = &c.params[0];
        eprintln!(
            "seed {seed}: b = {} ± {} mm (truth {b_true})",
            b.value, b.sigma
        );
        assert!(
            (b.value - b_true).abs() < 3.0 * b.sigma,
            "seed {seed}: b = {} ± {}",
            b.value,
            b.sigma
        );
        let d2 = diagnose::diagnose(&cal, Some(&val), &[&lost], &opts).expect("diagnose with it");
        let after = d2.baseline.val_rms.map(um_from_mm).expect("held-out");
        eprintln!("seed {seed} after: {} (floor {floor:.2} um)", summary(&d2));
        assert_eq!(d2.missing_effect, None, "seed {seed}: {}", summary(&d2));
        assert_ne!(d2.verdict_kind, VerdictKind::MissingEffect);
        assert!(
            after <= 1.5 * floor,
            "seed {seed}: held-out {after:.2} um, floor {floor:.2}"
        );
    }
}
