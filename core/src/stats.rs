//! Distribution tails for the statistical tests (the diagnosis's chi-square test of a residual
//! against the instruments' noise and nested F-test of a model extension; the online tracker's
//! drift gate). Regularised incomplete gamma and beta functions by their series and continued
//! fractions (Press et al., Numerical Recipes, 6.2 and 6.4), accurate to ~1e-12 over the ranges
//! used here.

/// ln Γ(x), x > 0 (Lanczos, g = 7, n = 9).
pub fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // reflection
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

const EPS: f64 = 1e-15;
const TINY: f64 = 1e-300;
const MAX_ITER: usize = 10_000;

/// Upper regularised incomplete gamma Q(a, x) = Γ(a, x) / Γ(a).
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    if x < a + 1.0 {
        // series for P
        let mut sum = 1.0 / a;
        let mut term = sum;
        let mut ap = a;
        for _ in 0..MAX_ITER {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * EPS {
                break;
            }
        }
        let p = sum * (-x + a * x.ln() - ln_gamma(a)).exp();
        (1.0 - p).max(0.0)
    } else {
        // continued fraction for Q (modified Lentz)
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..MAX_ITER {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            let del = lentz_step(an, b, &mut c, &mut d);
            h *= del;
            if (del - 1.0).abs() < EPS {
                break;
            }
        }
        (-x + a * x.ln() - ln_gamma(a)).exp() * h
    }
}

/// One term (a_n, b_n) of a continued fraction by the modified Lentz method: the running
/// ratios `c` and `d` updated (kept off zero by [`TINY`]), the factor the value is multiplied
/// by returned.
fn lentz_step(an: f64, bn: f64, c: &mut f64, d: &mut f64) -> f64 {
    *d = bn + an * *d;
    if d.abs() < TINY {
        *d = TINY;
    }
    *c = bn + an / *c;
    if c.abs() < TINY {
        *c = TINY;
    }
    *d = 1.0 / *d;
    *d * *c
}

/// P(χ²_ν ≥ x): the probability that noise alone gives a chi-square this large.
pub fn chi2_upper_tail(x: f64, nu: f64) -> f64 {
    gamma_q(nu / 2.0, x / 2.0)
}

/// P(Z ≥ z) of a standard normal Z (through erfc(x) = Q(½, x²)).
pub fn normal_upper_tail(z: f64) -> f64 {
    if z.is_nan() {
        return f64::NAN;
    }
    let half = 0.5 * gamma_q(0.5, 0.5 * z * z);
    if z >= 0.0 {
        half
    } else {
        1.0 - half
    }
}

/// Fisher's combination of independent p-values: P(χ²_{2k} ≥ −2 Σ ln p_i), the p-value
/// of the evidence of k independent tests together.
pub fn fisher_combined(p: &[f64]) -> f64 {
    let stat: f64 = p.iter().map(|v| -2.0 * v.max(f64::MIN_POSITIVE).ln()).sum();
    chi2_upper_tail(stat, 2.0 * p.len() as f64)
}

/// Continued fraction of the incomplete beta function.
fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..MAX_ITER {
        let m = m as f64;
        let m2 = 2.0 * m;
        h *= lentz_step(
            m * (b - m) * x / ((qam + m2) * (a + m2)),
            1.0,
            &mut c,
            &mut d,
        );
        let del = lentz_step(
            -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)),
            1.0,
            &mut c,
            &mut d,
        );
        h *= del;
        if (del - 1.0).abs() < EPS {
            break;
        }
    }
    h
}

/// Regularised incomplete beta I_x(a, b).
pub fn beta_i(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let bt = (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        bt * beta_cf(a, b, x) / a
    } else {
        1.0 - bt * beta_cf(b, a, 1.0 - x) / b
    }
}

/// P(F_{d1,d2} ≥ f): the p-value of a nested F-test.
pub fn f_upper_tail(f: f64, d1: f64, d2: f64) -> f64 {
    if !(f > 0.0) {
        return 1.0;
    }
    beta_i(d2 / 2.0, d1 / 2.0, d2 / (d2 + d1 * f))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_tail_matches_the_tables() {
        // Abramowitz & Stegun 26.2: Q(1.96) = 0.0249979, Q(3) = 0.0013499, Q(0) = 0.5
        assert!((normal_upper_tail(1.96) - 0.024_997_9).abs() < 1e-6);
        assert!((normal_upper_tail(3.0) - 0.001_349_9).abs() < 1e-6);
        assert!((normal_upper_tail(0.0) - 0.5).abs() < 1e-12);
        assert!((normal_upper_tail(-1.96) - 0.975_002_1).abs() < 1e-6);
    }

    #[test]
    fn fisher_combination_of_two_tests() {
        // two p-values of 0.01: −2 Σ ln p = 18.42, P(χ²_4 ≥ 18.42) = e^(−9.21)(1 + 9.21)
        let want = (-9.210_340_4_f64).exp() * (1.0 + 9.210_340_4);
        assert!((fisher_combined(&[0.01, 0.01]) - want).abs() < 1e-8);
    }

    #[test]
    fn ln_gamma_of_integers_is_log_factorial() {
        let mut f = 1.0f64;
        for n in 1..20 {
            assert!((ln_gamma(f64::from(n)) - f.ln()).abs() < 1e-10, "n = {n}");
            f *= f64::from(n);
        }
        // Γ(1/2) = √π
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-12);
    }

    #[test]
    fn chi2_tail_matches_closed_forms() {
        // ν = 2: P(χ² ≥ x) = exp(−x/2)
        for x in [0.1, 1.0, 5.0, 30.0] {
            assert!((chi2_upper_tail(x, 2.0) - (-x / 2.0f64).exp()).abs() < 1e-12);
        }
        // ν = 1: P = erfc(√(x/2)); at x = 3.841459 (the 95 % quantile) P = 0.05
        assert!((chi2_upper_tail(3.841_458_820_694_124, 1.0) - 0.05).abs() < 1e-9);
        // a large ν: the median is close to ν(1 − 2/(9ν))³
        let nu: f64 = 400.0;
        let median = nu * (1.0 - 2.0 / (9.0 * nu)).powi(3);
        assert!((chi2_upper_tail(median, nu) - 0.5).abs() < 1e-3);
    }

    #[test]
    fn f_tail_matches_known_quantiles() {
        // F(1, ∞-ish) ~ χ²_1: the 95 % quantile 3.84 for a large d2
        assert!((f_upper_tail(3.841_458_820_694_124, 1.0, 1e7) - 0.05).abs() < 1e-4);
        // F_{2,d2}: P(F ≥ f) = (1 + 2f/d2)^(−d2/2)
        for (f, d2) in [(1.0f64, 10.0f64), (4.0, 30.0), (0.3, 7.0)] {
            let exact = (1.0 + 2.0 * f / d2).powf(-d2 / 2.0);
            assert!((f_upper_tail(f, 2.0, d2) - exact).abs() < 1e-12, "{f} {d2}");
        }
    }
}
