//! Unit tests of the helpers; the file-level tests are in `core/tests/it/campaign_*.rs`.

use super::parse::parse_follower;
use super::write::{follower_text, followers_words, number};
use super::*;

#[test]
fn follower_digits_round_trip() {
    assert_eq!(parse_follower(""), Some([false; 4]));
    assert_eq!(parse_follower("23"), Some([false, true, true, false]));
    assert_eq!(parse_follower("32"), Some([false, true, true, false]));
    assert_eq!(parse_follower("1234"), Some([true; 4]));
    assert_eq!(parse_follower("22"), None);
    assert_eq!(parse_follower("5"), None);
    assert_eq!(parse_follower("2 3"), None);
    assert_eq!(follower_text([false, true, true, false]), "23");
    assert_eq!(follower_text([false; 4]), "");
    // none and "" are one value to every reader; people read none
    assert_eq!(parse_follower("none"), Some([false; 4]));
    assert_eq!(parse_follower(" none "), Some([false; 4]));
    assert_eq!(parse_follower("None"), None);
    assert_eq!(followers_words([false; 4]), "none");
    assert_eq!(followers_words([false, true, true, false]), "23");
}

#[test]
fn numbers_are_written_round_trip() {
    for v in [
        0.0,
        -0.0,
        1.0,
        -2611.0556,
        0.1 + 0.2,
        1e-300,
        f64::MIN_POSITIVE,
        5e-324,
        f64::MAX,
        -1.797_693_134_862_315_7e308,
        123_456_789_012_345_680.0,
        1e-5,
        9.99999e-6,
        std::f64::consts::PI,
    ] {
        let text = number(v);
        let back: f64 = text.parse().expect("written numbers parse");
        assert_eq!(back.to_bits(), v.to_bits(), "{v} written as {text}");
    }
    assert_eq!(number(1e-300), "1e-300");
    assert_eq!(number(2611.0556), "2611.0556");
}

#[test]
fn instrument_spellings_round_trip() {
    for i in Instrument::ALL {
        assert_eq!(i.as_str().parse::<Instrument>(), Ok(i));
        assert_eq!(i.to_string(), i.as_str());
    }
    assert!("LT".parse::<Instrument>().is_err());
    assert!("selfcal".parse::<Instrument>().is_err());
}

#[test]
fn instrument_classes() {
    let relative: Vec<_> = Instrument::ALL
        .into_iter()
        .filter(|i| i.is_relative())
        .map(Instrument::as_str)
        .collect();
    assert_eq!(relative, ["lt", "kgm", "dbb", "li_x", "li_y", "li_psi"]);
    assert!(Instrument::Circle.takes_reset());
    assert!(!Instrument::SelfCal.takes_reset());
    assert!(!Instrument::None.takes_reset());
}

/// Forces are measurements only where all four drives hold and every force was measured: a
/// live stream from a cell without force sensing has them NaN, which is no force row.
#[test]
fn drives_are_loaded_only_with_measured_forces() {
    let mut pose = MeasuredPose {
        t: 0.0,
        setup: "cell".into(),
        instrument: Instrument::None,
        reset: false,
        q: [2611.0, 2610.0, 789.0, 788.0],
        f: [100.0, -50.0, 20.0, -70.0],
        follower: [false; 4],
        x: None,
        y: None,
        r: None,
        psi: None,
        covariates: vec![],
        line: 0,
    };
    assert!(pose.drives_loaded());
    pose.f[1] = f64::NAN;
    assert!(!pose.drives_loaded(), "q2's force not measured");
    pose.f = [f64::NAN; 4];
    assert!(!pose.drives_loaded());
    pose.f = [0.0; 4];
    assert!(!pose.drives_loaded(), "no force recorded");
}
