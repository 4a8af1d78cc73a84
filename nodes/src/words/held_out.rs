//! The held-out data in words: the judge's line and sentence, the held-out campaign against
//! the calibration's ranges, a setup's return judged against the estimated noise.

use super::figures::{follows, p_is, prediction, um_with_sigma};
use crate::units::um_from_mm;
use rpkm_core::diagnose::held_out::coverage::{Coverage, Span};
use rpkm_core::diagnose::{HeldOutCheck, Undecided};
use std::fmt::Write as _;

/// The held-out judge's line, one for `rpkm diagnose` and `rpkm calibrate`: whether the
/// held-out data agree with the model, and why ([`held_out`]): at the floor or not, and
/// whether the held-out residual's structure fails it where its size does not.
pub fn held_out_judge(h: &HeldOutCheck) -> String {
    format!(
        "held-out judge: {}: {}",
        if h.agrees() {
            "the held-out data agree with the model"
        } else {
            "the held-out data do NOT agree with the model"
        },
        held_out(h)
    )
}

/// The held-out judge in words: "held-out RMS 12.7 µm (each setup's zero removed) against
/// the model's floor 5.4 µm (...; p = 1.2e-30)", and where the residual is structured, that
/// and its p-value, then what it follows.
pub fn held_out(h: &HeldOutCheck) -> String {
    let made_of = match h.nuisance_terms {
        0 => " and the calibration's own uncertainty".to_owned(),
        k => format!(
            ", the calibration's own uncertainty and the held-out campaign's own thermometer \
             error ({k} terms at their priors)"
        ),
    };
    let mut s = format!(
        "held-out RMS {:.1} µm (each setup's zero removed) against the model's floor {:.1} µm \
         (the noise {:.1} µm{made_of}; {})",
        um_from_mm(h.rms_relative()),
        um_from_mm(h.floor_relative),
        um_from_mm(h.noise_floor_relative()),
        p_is(h.p_value)
    );
    if h.structured {
        let _ = write!(
            s,
            "; the held-out residual is structured ({}), so the model does not pass",
            p_is(h.structure_p)
        );
    }
    if let Some(f) = &h.follows {
        let _ = write!(
            s,
            "; {}",
            follows(f).replacen("residual", "held-out residual", 1)
        );
    }
    s
}

/// The held-out campaign against the calibration's, where it reaches beyond: "the held-out
/// data lie OUTSIDE the calibration's range, the judge extrapolates: rate(temp_machine)
/// 0.012..0.173 K/min against the calibration's 0.000..0.061 K/min (0.11 K/min above, 2.8x
/// the calibration's largest magnitude)"; None where everything lies within.
pub fn coverage(c: &Coverage) -> Option<String> {
    let outside: Vec<String> = c.outside().map(span).collect();
    if outside.is_empty() {
        return None;
    }
    Some(format!(
        "the held-out data lie OUTSIDE the calibration's range, the judge extrapolates: {}",
        outside.join("; ")
    ))
}

/// The held-out readings of an instrument against the calibration's own readings of it, where
/// those saw less than the calibration as a whole: "the held-out lt readings lie outside the
/// calibration's own lt readings, what only lt measures is extrapolated there: temp_machine
/// 9.250..10.120 °C against the calibration's 8.344..8.390 °C (1.73 K above); to take it from
/// the data, measure lt across temp_machine 8.344..10.120 °C" (the one range that holds
/// both); None where none does.
pub fn instrument_coverage(c: &Coverage) -> Option<String> {
    let said: Vec<String> = c
        .instruments
        .iter()
        .filter_map(|s| {
            let i = s.instrument.as_deref()?;
            let unit = units(s).0;
            let (lo, hi) = (
                s.calibration.0.min(s.held_out.0),
                s.calibration.1.max(s.held_out.1),
            );
            Some(format!(
                "the held-out {i} readings lie outside the calibration's own {i} readings, what \
                 only {i} measures is extrapolated there: {}; to take it from the data, \
                 measure {i} across {} {lo:.3}..{hi:.3}{unit}",
                span(s),
                s.name
            ))
        })
        .collect();
    (!said.is_empty()).then(|| said.join("; "))
}

/// A span's unit, and its differences' (a thermometer's column, `temp_*` as the spec names
/// the temperatures, reads °C, its differences K).
fn units(s: &Span) -> (&'static str, &'static str) {
    let temperature = s.name.trim_start_matches("rate(").starts_with("temp");
    match (s.name.starts_with("rate("), temperature) {
        (true, true) => (" K/min", " K/min"),
        (true, false) => ("/min", "/min"),
        (false, true) => (" °C", " K"),
        (false, false) if s.name == "x" || s.name == "y" => (" mm", " mm"),
        (false, false) => ("", ""),
    }
}

/// One span in words, with by how much it reaches beyond.
fn span(s: &Span) -> String {
    let (unit, by_unit) = units(s);
    let mut by = Vec::new();
    if s.below > s.tolerance {
        by.push(format!("{:.2}{by_unit} below", s.below));
    }
    if s.above > s.tolerance {
        by.push(format!("{:.2}{by_unit} above", s.above));
    }
    let ratio = s
        .magnitude_ratio()
        .filter(|_| s.name.starts_with("rate("))
        .map_or(String::new(), |r| {
            format!(", {r:.1}x the calibration's largest magnitude")
        });
    format!(
        "{} {:.3}..{:.3}{unit} against the calibration's {:.3}..{:.3}{unit} ({}{ratio})",
        s.name,
        s.held_out.0,
        s.held_out.1,
        s.calibration.0,
        s.calibration.1,
        by.join(", ")
    )
}

/// The same return judged against the noise the campaign shows: "against the estimated
/// noise: moved, more than its noise (x +11 ± 9.0, y +4.1 ± 6.2 µm; p = 1.2e-3)" or
/// "against the estimated noise: within it (...)".
pub fn return_drift_estimated(d: &rpkm_core::returns::ReturnDrift) -> String {
    let parts: Vec<String> = d
        .components
        .iter()
        .map(|c| format!("{} {}", c.coordinate, um_with_sigma(c.value_mm, c.sigma_mm)))
        .collect();
    format!(
        "against the estimated noise: {} ({} µm; p = {:.2e})",
        if d.moved() {
            "moved, more than its noise"
        } else {
            "within it"
        },
        parts.join(", "),
        d.p_value
    )
}

/// A family whose parts the campaigns do not decide, in full: what the calibration needs,
/// what the prediction says of it, and what is kept. "the campaigns do not decide thermal's
/// parts: the calibration needs thermal:rods+frame+scales with ... over thermal:scales with
/// ... (chi2 3229.8 lower with 2.0 effective parameters more, p = 1.0e-204), but it predicts worse (held-out RMS,
/// ...); thermal:scales is kept, and neither is determined beyond these campaigns: measure
/// what tells the parts apart".
pub fn undecided(u: &Undecided) -> String {
    let p = &u.prediction;
    let predicts = if p.worse {
        "predicts worse"
    } else {
        "does not predict better"
    };
    format!(
        "the campaigns do not decide {}'s parts: the calibration needs {} over {} (chi2 \
         {:.1} lower with {:.1} effective parameters more, {}), but it {predicts} ({}); {} is kept, and \
         neither is determined beyond these campaigns: measure what tells the parts apart",
        family(u),
        u.needed.join(" with "),
        u.settled.join(" with "),
        u.chi2_fall,
        u.added,
        p_is(u.p_value),
        prediction(p),
        u.settled.join(" with ")
    )
}

/// The same in a clause of the verdict: "the campaigns do not decide thermal's parts (the
/// calibration needs thermal:rods+frame+scales, which predicts worse than thermal:scales)".
pub fn undecided_short(u: &Undecided) -> String {
    let needed = u.needed.first().map_or("", String::as_str);
    let settled = u.settled.first().map_or("", String::as_str);
    let predicts = if u.prediction.worse {
        "predicts worse than"
    } else {
        "predicts no better than"
    };
    format!(
        "the campaigns do not decide {}'s parts (the calibration needs {needed}, which \
         {predicts} {settled})",
        family(u)
    )
}

/// The family an undecided settle is of.
fn family(u: &Undecided) -> &str {
    u.needed
        .first()
        .map_or("", |n| rpkm_core::effects::family_of(n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rpkm_core::diagnose::{Prediction, RmsUnit};

    /// The undecided family's words hold the figures as measured, the prediction's unit and
    /// direction among them, and name what is kept.
    #[test]
    fn an_undecided_family_in_words() {
        let u = Undecided {
            settled: vec!["thermal:scales".to_owned()],
            needed: vec!["thermal:rods+frame+scales".to_owned()],
            chi2_fall: 3229.84,
            added: 2.04,
            p_value: 1.0e-204,
            prediction: Prediction {
                rms_before: 2.76,
                rms_after: 7.42,
                standard_error: 0.58,
                unit: RmsUnit::Sigma,
                support_p: 1.0,
                refitted: 0,
                better: false,
                worse: true,
                fall_read: -4.66,
                by_setup: true,
                resolution: 3.0,
            },
        };
        let long = undecided(&u);
        assert!(
            long.starts_with(
                "the campaigns do not decide thermal's parts: the calibration needs \
                 thermal:rods+frame+scales over thermal:scales (chi2 3229.8 lower with 2.0 \
                 effective parameters more, p = 1.0e-204), but it predicts worse \
                 (cross-validated (by setup) RMS, each row in its own noise (sigma), 2.76 -> \
                 7.42 sigma"
            ),
            "{long}"
        );
        assert!(long.contains("; thermal:scales is kept"), "{long}");
        assert_eq!(
            undecided_short(&u),
            "the campaigns do not decide thermal's parts (the calibration needs \
             thermal:rods+frame+scales, which predicts worse than thermal:scales)"
        );
    }

    /// An instrument's held-out readings beyond the calibration's own readings of it are said
    /// with the instrument and the figures; nothing is said where none is.
    #[test]
    fn an_instrument_beyond_its_own_calibration_readings_in_words() {
        let span = Span {
            name: "temp_machine".to_owned(),
            calibration: (10.661, 10.714),
            held_out: (13.516, 15.419),
            below: 0.0,
            above: 4.7051,
            tolerance: 0.03,
            instrument: Some("lt".to_owned()),
        };
        let mut c = Coverage {
            covariates: Vec::new(),
            rates: Vec::new(),
            poses: Vec::new(),
            instruments: vec![span],
        };
        assert_eq!(coverage(&c), None, "the campaign as a whole is within");
        assert_eq!(
            instrument_coverage(&c).as_deref(),
            Some(
                "the held-out lt readings lie outside the calibration's own lt readings, what \
                 only lt measures is extrapolated there: temp_machine 13.516..15.419 °C against \
                 the calibration's 10.661..10.714 °C (4.71 K above); to take it from the \
                 data, measure lt across temp_machine 10.661..15.419 °C"
            )
        );
        c.instruments.clear();
        assert_eq!(instrument_coverage(&c), None);
    }
}
