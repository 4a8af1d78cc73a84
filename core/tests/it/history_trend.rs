//! `history::trend` and `history::crossing`: a line and its crossing computed by hand, the
//! run after a break found, and the stated σ of slope and crossing date against the scatter
//! of 4,000 seeded draws (Monte Carlo).

use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rpkm_core::history::{crossing, trend, TrendPoint};

const DAY: f64 = 86_400.0;

/// `values` a day apart, each with σ 1.
fn daily(values: &[f64]) -> Vec<TrendPoint> {
    values
        .iter()
        .enumerate()
        .map(|(k, &v)| TrendPoint {
            t_s: k as f64 * DAY,
            value: v,
            sigma: 1.0,
        })
        .collect()
}

/// Four points, equal σ 1: t = 0, 1, 2, 3 days, values 0, 1, 2, 4. By hand: t̄ = 1.5 d,
/// mean 1.75, Σ(t − t̄)² = 5 d², slope = Σ(t − t̄)(v − v̄) / 5 = 6.5 / 5 = 1.3 per day, χ² =
/// Σ residual² = 0.3 on 2 dof (below 1: σ not widened), σ_slope = 1/√5 per day, σ_value =
/// 1/2. Crossing nominal 0 ± 5: (5 − 1.75)/1.3 = 2.5 d after t̄, t = 4 d, σ_t =
/// √(0.25 + 2.5² · 0.2)/1.3 = 0.9013 d.
#[test]
fn a_line_and_its_crossing_by_hand() {
    let points = daily(&[0.0, 1.0, 2.0, 4.0]);
    let t = trend(&points).expect("a trend");
    assert_eq!((t.from, t.points, t.dof), (0, 4, 2));
    assert!((t.t_mean_s - 1.5 * DAY).abs() < 1e-6);
    assert!((t.value - 1.75).abs() < 1e-12);
    assert!((t.slope * DAY - 1.3).abs() < 1e-12);
    assert!((t.sigma_slope * DAY - 0.2_f64.sqrt()).abs() < 1e-12);
    assert!((t.sigma_value - 0.5).abs() < 1e-12);
    assert!((t.chi2 - 0.3).abs() < 1e-12);
    let c = crossing(&t, 0.0, 5.0).expect("crossing");
    assert!((c.bound - 5.0).abs() < 1e-12);
    assert!((c.t_s / DAY - 4.0).abs() < 1e-9, "{}", c.t_s / DAY);
    let sigma = (0.25 + 2.5_f64.powi(2) * 0.2).sqrt() / 1.3;
    assert!(
        (c.sigma_s / DAY - sigma).abs() < 1e-9,
        "{}",
        c.sigma_s / DAY
    );
    // falling: it leaves by the lower bound
    let down: Vec<TrendPoint> = points
        .iter()
        .map(|p| TrendPoint {
            value: -p.value,
            ..*p
        })
        .collect();
    let c = crossing(&trend(&down).expect("trend"), 0.0, 5.0).expect("crossing");
    assert!((c.bound + 5.0).abs() < 1e-12 && (c.t_s / DAY - 4.0).abs() < 1e-9);
}

/// Flat at 0 for three points, a jump of 10 σ, then flat: the trend is that of the points
/// after the jump (the line through all of them is improbable), slope zero within its σ;
/// a line needs three points.
#[test]
fn the_trend_starts_after_the_last_break() {
    let points = daily(&[0.0, 0.0, 0.0, 10.0, 10.0, 10.0, 10.0]);
    let t = trend(&points).expect("trend");
    assert_eq!((t.from, t.points), (3, 4));
    assert!(t.slope.abs() < 1e-12 && (t.value - 10.0).abs() < 1e-12);
    assert!(trend(&points[..2]).is_none());
}

/// Ten points a month apart creeping 20 µm a month (σ 8 µm, the rods of a small campaign),
/// from −90 µm, tolerance ±100 µm (true crossing 9.5 months after the first): over 4,000
/// draws the stated σ of the slope and of the crossing date match the scatter of the
/// estimates (within 5 % and 15 %: the date is a ratio, its σ a linearisation), and the true
/// date lies within the stated 1σ in about 68 % of them (the widening by √(χ²/dof) makes it
/// somewhat more).
#[test]
fn the_stated_sigma_of_slope_and_crossing_hold_over_many_draws() {
    let month = 30.44 * DAY;
    let noise = Normal::new(0.0, 0.008).expect("normal");
    let mut rng = StdRng::seed_from_u64(39);
    let truth = |t: f64| -0.090 + 0.020 * t / month;
    let true_crossing = 9.5 * month;
    let (mut slopes, mut sigma_slope, mut dates, mut sigma_date) = (vec![], vec![], vec![], vec![]);
    let (mut covered, mut cut) = (0, 0);
    let draws = 4000;
    for _ in 0..draws {
        let points: Vec<TrendPoint> = (0..10)
            .map(|k| {
                let t = f64::from(k) * month;
                TrendPoint {
                    t_s: t,
                    value: truth(t) + noise.sample(&mut rng),
                    sigma: 0.008,
                }
            })
            .collect();
        let t = trend(&points).expect("trend");
        let c = crossing(&t, 0.0, 0.1).expect("crossing");
        covered += usize::from((c.t_s - true_crossing).abs() <= c.sigma_s);
        // a run cut short by a χ² beyond 1e-3 (about 1 draw in 1,000 per cut tested): its
        // few points scatter widely, as their σ say, and would dominate the spread below
        if t.from > 0 {
            cut += 1;
            continue;
        }
        slopes.push(t.slope);
        sigma_slope.push(t.sigma_slope);
        dates.push(c.t_s);
        sigma_date.push(c.sigma_s);
    }
    let spread = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
    };
    let median = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s[s.len() / 2]
    };
    let ratio_slope = median(&sigma_slope) / spread(&slopes);
    let ratio_date = median(&sigma_date) / spread(&dates);
    let coverage = covered as f64 / f64::from(draws);
    eprintln!(
        "slope σ / scatter {ratio_slope:.3}, date σ / scatter {ratio_date:.3}, 1σ coverage \
         {coverage:.3}, runs cut {cut}"
    );
    assert!(cut <= 20, "{cut} runs cut short of {draws}");
    assert!(
        (0.95..1.05).contains(&ratio_slope),
        "slope σ / scatter {ratio_slope:.3}"
    );
    assert!(
        (0.85..1.15).contains(&ratio_date),
        "date σ / scatter {ratio_date:.3}"
    );
    assert!((0.64..0.80).contains(&coverage), "coverage {coverage:.3}");
}
