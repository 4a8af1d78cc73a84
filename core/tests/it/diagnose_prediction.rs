//! The prediction's evidence (`Prediction::compared`, `support_p`): errors before a change
//! regressed on the change it makes, against normal theory on errors drawn here and an
//! independent numpy simulation of the same designs. Under the null its p-values are
//! uniform; a change the errors hold is supported where the fall of the RMS is not yet
//! decisive; a change fitted to the very errors compared follows them by construction and
//! is judged by its fall beyond what the fit takes from noise.

use rpkm_core::diagnose::Prediction;

/// Standard normal draws from a fixed seed (xorshift64*, Box-Muller): the test's own
/// independent noise, no dependency of the model's.
struct Normal(u64);

impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn draw(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
    fn draws(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.draw()).collect()
    }
}

/// A change that the errors do not hold (drawn apart from them, as a calibration campaign's
/// fit is from held-out noise): over 4,000 trials the p-values are uniform, 5 % ± 1 % of
/// them below 0.05 and 50 % ± 2 % below 0.5.
#[test]
fn a_change_the_errors_do_not_hold_has_uniform_p_values() {
    let mut g = Normal(0x9e37_79b9_7f4a_7c15);
    let (trials, n): (usize, usize) = (4_000, 200);
    let p: Vec<f64> = (0..trials)
        .map(|_| {
            let before = g.draws(n);
            let change: Vec<f64> = g.draws(n).iter().map(|c| 0.3 * c).collect();
            let after: Vec<f64> = before.iter().zip(&change).map(|(b, c)| b - c).collect();
            Prediction::compared(&before, &after)
                .expect("compared")
                .support_p
        })
        .collect();
    let below = |level: f64| p.iter().filter(|&&p| p < level).count() as f64 / trials as f64;
    assert!(
        (below(0.05) - 0.05).abs() < 0.01,
        "{} below 0.05",
        below(0.05)
    );
    assert!((below(0.5) - 0.5).abs() < 0.02, "{} below 0.5", below(0.5));
}

/// Errors that hold a ramp (a tracker creeping after its zero, in the half of the errors
/// along its beam: 1.2 σ at its ends) and the change that removes it: over 500 trials the
/// regression's p-value is below 1e-4 in every one, while the fall of the RMS in its
/// standard errors (what judged a prediction before) reaches that in about 29 % (numpy,
/// the same design: t-values 6.24 and 3.25 on average).
#[test]
fn a_change_the_errors_hold_is_supported_where_the_fall_is_not_decisive() {
    let mut g = Normal(7);
    let (trials, n): (usize, usize) = (500, 200);
    let ramp: Vec<f64> = (0..n)
        .map(|i| {
            if i % 2 == 1 {
                2.4 * ((i as f64 / n as f64) - 0.5)
            } else {
                0.0
            }
        })
        .collect();
    let (mut supported, mut fallen) = (0, 0);
    for _ in 0..trials {
        let before: Vec<f64> = g.draws(n).iter().zip(&ramp).map(|(e, r)| e + r).collect();
        let after: Vec<f64> = before.iter().zip(&ramp).map(|(b, r)| b - r).collect();
        let p = Prediction::compared(&before, &after).expect("compared");
        supported += usize::from(p.support_p < 1e-4);
        let fall = (p.rms_before - p.rms_after) / p.standard_error;
        fallen += usize::from(rpkm_core::stats::normal_upper_tail(fall) < 1e-4);
    }
    assert!(
        supported as f64 >= 0.99 * trials as f64,
        "{supported} of {trials} supported"
    );
    assert!(
        (fallen as f64) < 0.45 * trials as f64,
        "{fallen} of {trials} fell decisively"
    );
}

/// One parameter fitted to the very errors compared (an instrument's angle in the held-out
/// setup, refitted there): on pure noise the regression supports it by construction (its
/// t-value is |N(0, 1)|: its p-value never above 0.5 in 4,000 trials, below 0.05 in 10 % ±
/// 2 % where noise alone gives 5 %), the fall beyond what fitting takes from noise in at
/// most 0.5 % (numpy, the same design: 0.1 %); errors that hold the fitted shape at 0.6 σ are
/// supported below 0.05 in 98 % ± 2 % (numpy: 98.2 %).
#[test]
fn a_change_fitted_to_the_errors_is_judged_by_its_fall_beyond_the_fit() {
    let mut g = Normal(11);
    let (trials, n): (usize, usize) = (4_000, 100);
    let (mut above_half, mut raw_below, mut refit_below, mut held_below) = (0, 0, 0, 0);
    for _ in 0..trials {
        let shape = g.draws(n);
        let size: f64 = shape.iter().map(|s| s * s).sum();
        for held in [0.0, 0.6] {
            let before: Vec<f64> = g
                .draws(n)
                .iter()
                .zip(&shape)
                .map(|(e, s)| e + held * s)
                .collect();
            let c = before.iter().zip(&shape).map(|(b, s)| b * s).sum::<f64>() / size;
            let after: Vec<f64> = before.iter().zip(&shape).map(|(b, s)| b - c * s).collect();
            let p = Prediction::compared(&before, &after).expect("compared");
            let refit = p.refit(1, n);
            assert_eq!(refit.refitted, 1);
            if held == 0.0 {
                above_half += usize::from(p.support_p > 0.5);
                raw_below += usize::from(p.support_p < 0.05);
                refit_below += usize::from(refit.support_p < 0.05);
            } else {
                held_below += usize::from(refit.support_p < 0.05);
            }
        }
    }
    let share = |k: usize| k as f64 / trials as f64;
    assert_eq!(above_half, 0);
    assert!(
        (share(raw_below) - 0.1).abs() < 0.02,
        "{} raw below 0.05",
        share(raw_below)
    );
    assert!(
        share(refit_below) <= 0.005,
        "{} refitted below 0.05",
        share(refit_below)
    );
    assert!(
        (share(held_below) - 0.98).abs() < 0.02,
        "{} held below 0.05",
        share(held_below)
    );
}

/// A change's resolution is the regression's expected t-value were the change right; the
/// held-out errors contradict a change they resolve (4 or more), do not follow (support
/// p ≥ 0.05) and whose RMS does not fall. Over 2,000 trials of 200 errors: errors holding a
/// change of √ΣΔ² = 5 s read the regression's z at its resolution on average (4.71, normal
/// theory: their RMS holds the change too) and contradict it at most 1 % of the time (the
/// regression alone 0.1 %, N(4.71, 1) below 1.64; their RMS falls besides); the same change
/// drawn apart from them is contradicted in 95 % (uniform p-values, ± 1.5 %; its RMS falls
/// by chance in 0.6 %); a change of 1.5 s is never resolved, and is left to the setups left
/// out.
#[test]
fn held_out_errors_contradict_a_change_they_resolve_and_do_not_follow() {
    let mut g = Normal(23);
    let (trials, n): (usize, usize) = (2_000, 200);
    let shaped = |g: &mut Normal, size: f64| {
        let c = g.draws(n);
        let norm = c.iter().map(|v| v * v).sum::<f64>().sqrt();
        c.iter().map(|v| v * size / norm).collect::<Vec<f64>>()
    };
    let (mut z_sum, mut held_contradicted, mut apart_contradicted) = (0.0, 0, 0);
    for _ in 0..trials {
        let noise = g.draws(n);
        let s = (noise.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        let change = shaped(&mut g, 5.0 * s);
        // the errors hold the change: before = noise + change, after = noise
        let before: Vec<f64> = noise.iter().zip(&change).map(|(e, c)| e + c).collect();
        let held = Prediction::compared(&before, &noise).expect("compared");
        z_sum += normal_quantile_upper(held.support_p);
        held_contradicted += usize::from(held.contradicted());
        // drawn apart: the same change taken from errors that do not hold it
        let after: Vec<f64> = noise.iter().zip(&change).map(|(e, c)| e - c).collect();
        let apart = Prediction::compared(&noise, &after).expect("compared");
        apart_contradicted += usize::from(apart.contradicted());
        let small = shaped(&mut g, 1.5 * s);
        let after: Vec<f64> = noise.iter().zip(&small).map(|(e, c)| e - c).collect();
        let small = Prediction::compared(&noise, &after).expect("compared");
        assert!(
            !small.contradicted() && small.resolution < 2.0,
            "resolution {}",
            small.resolution
        );
    }
    let z_mean = z_sum / trials as f64;
    let expected = 5.0 / (1.0_f64 + 25.0 / n as f64).sqrt();
    assert!(
        (z_mean - expected).abs() < 0.1,
        "mean z {z_mean} against {expected}"
    );
    let share = |k: usize| k as f64 / trials as f64;
    assert!(
        share(held_contradicted) <= 0.01,
        "{}",
        share(held_contradicted)
    );
    assert!(
        (share(apart_contradicted) - 0.95).abs() <= 0.015,
        "{}",
        share(apart_contradicted)
    );
}

/// The upper-tail normal quantile of `p` (bisection on erfc): the test's own, not the
/// model's.
fn normal_quantile_upper(p: f64) -> f64 {
    let upper = |z: f64| 0.5 * libm_erfc(z / std::f64::consts::SQRT_2);
    let (mut lo, mut hi) = (-10.0, 40.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if upper(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// erfc by Numerical Recipes' erfcc approximation (relative error below 1.2e-7).
fn libm_erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}
