//! A figure with its uncertainty, the one way every text and report prints it, and what a
//! condition number means where it is no number, a p-value, what a residual follows.

use crate::units::um_from_mm;
use rpkm_core::diagnose::structure::sparse::Pointer;
use rpkm_core::diagnose::{Prediction, RmsUnit};

/// A value with its standard deviation, the one way every text and report prints them: σ to
/// two significant digits and the value to the same place, in a unit that shows both (mm as
/// µm, rad and mrad as µrad, a ratio as ppm): "9.990 ± 0.040 µm", "-0.6 ± 1.3 µm",
/// "41.8 ± 2.4 ppm", "1230 ± 250 µm". A σ that is not a positive number is said so.
pub fn with_sigma(value: f64, sigma: f64, unit: &str) -> String {
    let (k, unit) = display_unit(unit);
    let (v, s) = (value * k, sigma * k);
    if !(s > 0.0 && s.is_finite()) {
        let why = if s == 0.0 { "exact" } else { "σ undetermined" };
        return format!("{v:.3} {unit} ({why})");
    }
    // the place of σ's second significant digit
    let e = s.log10().floor();
    let decimals = rpkm_core::convert::floor_count(1.0 - e);
    let place = 10f64.powf(e - 1.0);
    let round = |x: f64| (x / place).round() * place;
    // no "-0.000": a value that rounds to zero has no sign
    let v = if round(v) == 0.0 { 0.0 } else { round(v) };
    format!("{v:.decimals$} ± {:.decimals$} {unit}", round(s))
}

/// A unit as a person reads it: the JSON's `um`, `urad` as `µm`, `µrad` (the JSON keeps the
/// ASCII spelling other tools read); every other unit as it is.
pub fn unit_label(unit: &str) -> &str {
    match unit {
        "um" => "µm",
        "urad" => "µrad",
        other => other,
    }
}

/// The factor from a quantity's unit to the one it is shown in, and that unit.
pub(super) fn display_unit(unit: &str) -> (f64, &str) {
    match unit {
        "mm" => (1e3, "µm"),
        "rad" => (1e6, "µrad"),
        "mrad" => (1e3, "µrad"),
        "" | "1" => (1e6, "ppm"),
        "mm/K" => (1e3, "µm/K"),
        "mm/h" => (1e3, "µm/h"),
        "rad/K" => (1e6, "µrad/K"),
        "rad/h" => (1e6, "µrad/h"),
        "1/K" => (1e6, "ppm/K"),
        "um" => (1.0, "µm"),
        "urad" => (1.0, "µrad"),
        other => (1.0, other),
    }
}

/// The identification's condition number for people: the number where it is finite; where it
/// is not (the JSON's null), what that means: the measurements alone leave some parameter
/// combinations undetermined, and the prior (the manufacturing tolerances) holds them.
pub fn condition(number: f64, determined: Option<(usize, usize)>) -> String {
    if number.is_finite() {
        return format!("{number:.1}");
    }
    if number.is_nan() {
        return "none computed".to_owned();
    }
    let held = match determined {
        Some((n, of)) => format!(
            "; {} of {of} parameter combinations are not determined better than their \
             tolerance, and the prior (the manufacturing tolerances) holds them",
            of.saturating_sub(n)
        ),
        None => String::new(),
    };
    format!(
        "infinite: the measurements alone leave some directions of the parameters \
         undetermined{held}"
    )
}

/// The condition number in a status line's few words: the number, "infinite (the prior holds
/// what the measurements leave)", or "-" where none was computed.
pub fn condition_short(number: f64) -> String {
    if number.is_finite() {
        format!("{number:.1}")
    } else if number.is_nan() {
        "-".to_owned()
    } else {
        "infinite (the prior holds what the measurements leave)".to_owned()
    }
}

/// "the lt x residual follows temp_machine (r = 0.93, and equally q2)".
pub fn follows(p: &Pointer) -> String {
    let tied = if p.ties.is_empty() {
        String::new()
    } else {
        format!(", and equally {}", p.ties.join(", "))
    };
    format!(
        "the {} {} residual follows {} (r = {:.2}{tied})",
        p.instrument, p.direction, p.feature, p.r
    )
}

/// "p = 1.2e-3", or "p < 1e-300" where the p-value underflowed to 0 (it is no probability
/// of 0).
pub fn p_is(p: f64) -> String {
    if p > 0.0 || p.is_nan() {
        format!("p = {p:.1e}")
    } else {
        "p < 1e-300".to_owned()
    }
}

/// `value ± sigma` in µm, the value to the digits of σ's two significant ones.
pub(super) fn um_with_sigma(value_mm: f64, sigma_mm: f64) -> String {
    let (v, s) = (um_from_mm(value_mm), um_from_mm(sigma_mm));
    // the decimals that show σ's second significant digit: 1 − ⌊log10 σ⌋, at least 0
    let digits = if s > 0.0 && s.is_finite() {
        11usize.saturating_sub(rpkm_core::convert::floor_count(s.log10() + 10.0))
    } else {
        1
    };
    format!("{v:+.digits$} ± {s:.digits$}")
}

/// "held-out RMS 17.98 -> 12.69 µm (± 2.11; the errors follow the change, p = 3.2e-8)", or
/// "(± 2.11; 1 parameter fitted with them, the fall beyond what that takes from noise p =
/// 2.0e-9)".
pub(super) fn prediction(p: &Prediction) -> String {
    let support = match p.refitted {
        0 => format!("the errors follow the change, p = {:.1e}", p.support_p),
        k => format!(
            "{k} parameter{} fitted with them, the fall beyond what that takes from noise \
             p = {:.1e}",
            if k == 1 { "" } else { "s" },
            p.support_p
        ),
    };
    let what = match (p.by_setup, p.unit) {
        (true, _) => "cross-validated (by setup) RMS, each row in its own noise (sigma),",
        (false, RmsUnit::Sigma) => "held-out RMS, each reading in its own noise (sigma),",
        (false, RmsUnit::Um) => "held-out RMS with each setup's zero removed",
    };
    format!(
        "{what} {:.2} -> {:.2} {} (± {:.2}; {support})",
        p.rms_before,
        p.rms_after,
        match p.unit {
            RmsUnit::Um => "µm",
            RmsUnit::Sigma => "sigma",
        },
        p.standard_error
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the user read as "b4 = 0.010 ± 0.000 mm" and "c1 = -0.0000 ± 0.0001 mm": σ to
    /// two significant digits, the value to the same place, in µm (µrad, ppm); σ rounded like
    /// the value (250, not 253); no negative zero.
    #[test]
    fn a_value_shows_its_sigma() {
        assert_eq!(with_sigma(0.00999, 0.00004, "mm"), "9.990 ± 0.040 µm");
        assert_eq!(with_sigma(-0.000_02, 0.000_13, "mm"), "-0.02 ± 0.13 µm");
        assert_eq!(with_sigma(-0.000_002, 0.000_13, "mm"), "0.00 ± 0.13 µm");
        assert_eq!(with_sigma(0.002_41, 0.000_05, "mm"), "2.410 ± 0.050 µm");
        assert_eq!(with_sigma(1.234, 0.253, "mm"), "1230 ± 250 µm");
        assert_eq!(with_sigma(0.081, 0.0024, "mrad"), "81.0 ± 2.4 µrad");
        assert_eq!(with_sigma(41.83, 2.37, "ppm"), "41.8 ± 2.4 ppm");
        assert_eq!(with_sigma(4.2e-5, 1.1e-6, "1"), "42.0 ± 1.1 ppm");
        assert_eq!(
            with_sigma(1.02, 0.013, "x default"),
            "1.020 ± 0.013 x default"
        );
        assert_eq!(
            with_sigma(0.5, f64::INFINITY, "mm"),
            "500.000 µm (σ undetermined)"
        );
    }
}
