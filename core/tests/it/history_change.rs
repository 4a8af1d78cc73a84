//! `history::change`: the change between two calibrations against a case computed by hand,
//! and against the twin: calibrations of one machine that did not change give changes whose
//! stated σ hold (their z spread about 1, no flag), and a crash of rod 3 between two is
//! flagged as l3 alone, by the amount the twin moved it.

use nalgebra::SMatrix;
use rpkm_core::calib::{self, Options, Prior, Request};
use rpkm_core::campaign::Campaign;
use rpkm_core::history::{change, ChangeVerdict, Estimate, Seen};
use rpkm_core::params::{Model, Params, L1, L3, N_PARAMS, XA1R};
use rpkm_twin::{Twin, TwinConfig};

/// Tolerances of the default prior (0.1 mm, 1 mrad) per parameter.
fn tolerance() -> [f64; N_PARAMS] {
    std::array::from_fn(|i| Prior::default().sigma(i))
}

/// An estimate at nominal whose every parameter sits at its prior (undetermined).
fn at_prior(t_s: f64) -> Estimate {
    let tol = tolerance();
    Estimate {
        t_s,
        model: Model::M29,
        params: Params::nominal(),
        covariance: SMatrix::from_fn(|i, j| if i == j { tol[i] * tol[i] } else { 0.0 }),
        tolerance: tol,
    }
}

/// Two calibrations: l1 and l3 determined by both (correlated in the first), xa1r by the
/// second only. By hand: l1 +0.03 ± √(1e-4 + 4e-4) = ±0.02236 (1.34 σ), l3 +0.1 ± √2e-4 =
/// ±0.01414 (7.07 σ); over l1, l3 in tolerance units C = [[0.05, 0.005], [0.005, 0.02]],
/// d = [0.3, 1.0]: χ² = dᵀC⁻¹d = 0.0488 / 0.000975 = 50.0513 on 2 directions, p = e^(−χ²/2).
#[test]
fn a_change_computed_by_hand() {
    let mut a = at_prior(0.0);
    a.covariance[(L1, L1)] = 1e-4;
    a.covariance[(L3, L3)] = 1e-4;
    a.covariance[(L1, L3)] = 0.5e-4;
    a.covariance[(L3, L1)] = 0.5e-4;
    let mut b = at_prior(86_400.0);
    b.covariance[(L1, L1)] = 4e-4;
    b.covariance[(L3, L3)] = 1e-4;
    b.covariance[(XA1R, XA1R)] = 1e-4;
    b.params[L1] += 0.03;
    b.params[L3] += 0.1;
    b.params[XA1R] += 0.5;
    let c = change(&a, &b);
    assert_eq!(c.params.len(), N_PARAMS);
    let l1 = c.params[L1];
    assert!((l1.change - 0.03).abs() < 1e-12);
    assert!((l1.sigma - 5e-4_f64.sqrt()).abs() < 1e-12);
    assert_eq!(l1.seen, Seen::Both);
    assert!((l1.z().unwrap_or(f64::NAN) - 1.341_640_786).abs() < 1e-6);
    assert!(!l1.flagged());
    let l3 = c.params[L3];
    assert!((l3.z().unwrap_or(f64::NAN) - 7.071_067_81).abs() < 1e-6);
    assert!(l3.flagged());
    // a large change that the first calibration did not see is unknown, not flagged
    let xa1r = c.params[XA1R];
    assert_eq!(
        (xa1r.seen, xa1r.z(), xa1r.flagged()),
        (Seen::After, None, false)
    );
    assert_eq!(c.params[XA1R + 1].seen, Seen::Neither);
    assert_eq!(
        c.flagged().iter().map(|p| p.param).collect::<Vec<_>>(),
        [L3]
    );
    let joint = c.joint.expect("l1 and l3 are determined by both");
    assert_eq!(joint.directions, 2);
    assert!(
        (joint.chi2 - 0.0488 / 0.000_975).abs() < 1e-9,
        "{}",
        joint.chi2
    );
    let p = (-joint.chi2 / 2.0).exp();
    assert!(
        (joint.p_value / p - 1.0).abs() < 1e-6,
        "{} vs {p}",
        joint.p_value
    );
    // the largest single change, l3 at 5√2 σ, as the largest of the 2 both determined:
    // 2·Q(5√2) = erfc(5) = 1.5374597944e-12 alone, 1 − (1 − that)² as the largest of two
    let largest = c.largest.expect("l1 and l3 are determined by both");
    assert_eq!((largest.param, largest.among), (L3, 2));
    let erfc5 = 1.537_459_794_4e-12;
    assert!((largest.p_single / erfc5 - 1.0).abs() < 1e-6, "{largest:?}");
    let of_two = 2.0 * erfc5 - erfc5 * erfc5;
    assert!(
        (largest.p_largest / of_two - 1.0).abs() < 1e-6,
        "{largest:?}"
    );
    assert_eq!(c.verdict(), Some(ChangeVerdict::Changed));
}

/// The calibration every command makes (tolerance prior, noise estimated) as an estimate.
fn calibrated(campaign: &Campaign, t_s: f64) -> Estimate {
    let opts = Options {
        threads: 1,
        ..Options::default()
    };
    let start = Params::nominal();
    let (cal, _) = calib::calibrate(&Request {
        noise: calib::Noise::ESTIMATE,
        ..Request::new(campaign, &start, &opts)
    })
    .expect("calibration");
    Estimate {
        t_s,
        model: cal.model,
        params: cal.params,
        covariance: cal.covariance,
        tolerance: tolerance(),
    }
}

/// A small campaign (grid encoder and platform angle, 236 poses: l1..l5 to ~8 µm).
fn campaign(twin: &mut Twin) -> Campaign {
    twin.campaign_by_names(&["kgm", "li_psi"], 0)
        .expect("twin campaign")
}

/// Six calibrations of one unchanged machine, each from fresh noise: the 5 changes between
/// consecutive ones over every parameter both determined (35: l1..l5, γ1, γ2) have z whose
/// RMS is near 1 (the stated σ are the scatter's: at most 1.25, and above 0.5 where the
/// prior's pull makes them conservative) and none beyond 4σ (3σ is passed by one of 370
/// changes of an unchanged machine: here l1 by 3.08σ once); the joint χ² is not improbable.
/// Then rod 3 is bent by 0.1 mm: the next change flags l3 alone, within 3σ of 0.1 mm.
#[test]
fn calibrations_of_one_machine_change_by_their_sigma_and_a_crash_is_l3() {
    let mut twin = Twin::new(TwinConfig {
        seed: 21,
        ..Default::default()
    })
    .expect("twin");
    let runs: Vec<Estimate> = (0..6)
        .map(|k| calibrated(&campaign(&mut twin), 86_400.0 * f64::from(k)))
        .collect();
    let mut z = Vec::new();
    for pair in runs.windows(2) {
        let c = change(&pair[0], &pair[1]);
        z.extend(
            c.params
                .iter()
                .filter_map(rpkm_core::history::ParamChange::z),
        );
        let joint = c.joint.expect("determined directions");
        assert!(joint.p_value > 1e-3, "{joint:?}");
    }
    assert!(z.len() >= 20, "{} determined changes", z.len());
    let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
    assert!(
        (0.5..=1.25).contains(&rms),
        "z RMS {rms:.3} over {}",
        z.len()
    );
    assert!(z.iter().all(|v| v.abs() < 4.0), "{z:?}");
    assert!(twin.shift(L3, 0.1));
    let crashed = calibrated(&campaign(&mut twin), 7.0 * 86_400.0);
    let c = change(&runs[5], &crashed);
    let flagged: Vec<usize> = c.flagged().iter().map(|p| p.param).collect();
    assert_eq!(flagged, [L3], "{:?}", c.flagged());
    let l3 = c.params[L3];
    assert!(
        (l3.change - 0.1).abs() < 3.0 * l3.sigma,
        "l3 {:+.4} ± {:.4} mm",
        l3.change,
        l3.sigma
    );
    assert!(c.joint.expect("joint").p_value < 1e-6);
}
