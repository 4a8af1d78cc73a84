//! Checks of the charts against what they must show, independent of how they draw it.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

use super::machine::Machine;
use super::maps::{diverging, round_length, round_up};
use super::*;
use rpkm_core::params::{Params, RODS};

/// Every rod of the drawn machine has its length: the joints come from the geometry, not
/// from hand-placed coordinates (spec check values: q at (0, 1700)).
#[test]
fn machine_joints_close_every_rod() {
    let p = Params::nominal();
    let m = Machine::at(&p, 0.0, 1700.0, (700.0, 2700.0)).expect("nominal pose");
    for (i, (a, b)) in m.rods.iter().enumerate() {
        let l = p[RODS[i].l];
        assert!(
            ((a - b).norm() - l).abs() < 1e-6,
            "rod {}: {} vs {l}",
            i + 1,
            (a - b).norm()
        );
    }
    let q = [2611.0556, 2611.0556, 788.9444, 788.9444];
    for (k, (drawn, spec)) in m.q.iter().zip(q).enumerate() {
        assert!((drawn - spec).abs() < 1e-3, "q{}: {drawn} vs {spec}", k + 1);
    }
    // guides stand at d1 = -1460 and d2 = 1460 and run along y
    assert!((m.guides[0].0.x + 1460.0).abs() < 1e-9 && (m.guides[1].1.x - 1460.0).abs() < 1e-9);
}

/// Zero is white, the ends are the darkest blue and red, and the scale is symmetric.
#[test]
fn colour_scale_is_centred_at_zero() {
    assert_eq!(diverging(0.0, 5.0), "#f7f7f7");
    assert_eq!(diverging(5.0, 5.0), "#b2182b");
    assert_eq!(diverging(-9.0, 5.0), "#2166ac");
    assert_eq!(diverging(f64::NAN, 5.0), "#f7f7f7");
    assert_ne!(diverging(1.0, 5.0), diverging(-1.0, 5.0));
}

#[test]
fn reference_lengths_are_round() {
    assert_eq!(round_length(43.0), 50.0);
    assert_eq!(round_length(14.0), 10.0);
    assert_eq!(round_length(0.018), 0.02);
    assert_eq!(round_up(2.58), 3.0);
    assert_eq!(round_up(153.0), 200.0);
    assert_eq!(round_up(0.04), 0.04);
}

/// One bar per category and series, each with its value on hover; a NaN is an empty bar.
#[test]
fn bar_chart_has_one_bar_per_category_and_series() {
    let cats: Vec<String> = ["l1", "d2 & <g2>"]
        .iter()
        .map(std::string::ToString::to_string)
        .collect();
    let svg = bar_chart(
        "t",
        "v",
        &cats,
        &[
            ("a".into(), vec![1.0, f64::NAN]),
            ("b".into(), vec![2.0, 3.0]),
        ],
        &BarOptions::default(),
    );
    assert_eq!(svg.matches("class=\"bar\"").count(), 4);
    assert!(svg.contains("d2 &amp; &lt;g2&gt;: b: 3.0000"), "{svg}");
    assert!(svg.contains("no value") && !svg.contains("NaN"));
    assert_eq!(
        svg,
        bar_chart(
            "t",
            "v",
            &cats,
            &[
                ("a".into(), vec![1.0, f64::NAN]),
                ("b".into(), vec![2.0, 3.0])
            ],
            &BarOptions::default()
        )
    );
}

#[test]
fn escape_covers_markup_and_control_characters() {
    assert_eq!(escape("a<b>&\"'\u{1}"), "a&lt;b&gt;&amp;&quot;&#39;");
}
