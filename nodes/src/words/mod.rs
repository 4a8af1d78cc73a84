//! Sentences for people, built from the core's numbers: a diagnosis's verdict, a candidate's
//! evidence, what a residual follows, how the verdict was tested. The core returns named
//! figures (`rpkm_core::diagnose`); the words and their units live here, once, for the
//! terminal, the HTML report and the JSON's text fields alike.

use crate::units::um_from_mm;
use rpkm_core::diagnose::structure::carried::Carried;
use rpkm_core::diagnose::structure::neighbours::Neighbours;
use rpkm_core::diagnose::structure::periodic::Periodic;
use rpkm_core::diagnose::{
    Candidate, EvidenceOf, Judged, ModelDiagnosis, ModelTrial, Outcome, Test, VerdictKind,
};
use rpkm_core::effects::Family;
use rpkm_core::online::{Drift, DriftInput, FOLLOWS};
use rpkm_core::params::{unit, Model, Unit, NAMES};
use std::fmt::Write as _;

mod figures;
mod held_out;
mod noise;

pub use figures::{condition, condition_short, follows, p_is, unit_label, with_sigma};
use figures::{prediction, um_with_sigma};
pub use held_out::{
    coverage, held_out, held_out_judge, instrument_coverage, return_drift_estimated, undecided,
    undecided_short,
};
pub use noise::{estimated_level, noise, rated_by};

/// The drift WARN's words, claiming no more than the path identifies: "l3 +48 µm in 6 min
/// (+12.00 ± 0.30 µm/K), follows temp_machine (r = 0.98)" where one candidate explains it with
/// the margin; else "l1..l5 alike in 2 min, the path cannot tell which: l3 +19 µm, l1 +15 µm,
/// ..." with the change each would need (they differ in size and sign), and no rate; "; 22
/// other parameters explain it alike" where parameters outside the candidates do (the
/// temperature named `temp_name`).
pub fn drift(d: &Drift, temp_name: &str) -> String {
    let (k, unit) = scaled_unit(d.param);
    let per = match d.input {
        DriftInput::Temperature(_) => "K",
        DriftInput::Time | DriftInput::Unknown => "h",
    };
    let minutes = d.over_s / 60.0;
    let mut s = if d.is_identified() {
        let base = match rpkm_core::params::unit(d.param) {
            Unit::Mm => "mm",
            Unit::Rad => "rad",
        };
        format!(
            "{} {:+.0} {unit} in {minutes:.0} min ({}{})",
            NAMES[d.param],
            d.change * k,
            if d.rate >= 0.0 { "+" } else { "" },
            with_sigma(d.rate, d.rate_sigma, &format!("{base}/{per}"))
        )
    } else {
        // the best first, the others by name
        let mut named: Vec<(usize, f64)> = d.named().collect();
        named[1..].sort_by_key(|(i, _)| NAMES[*i]);
        let each: Vec<String> = named
            .iter()
            .map(|&(i, c)| {
                let (k, unit) = scaled_unit(i);
                format!("{} {:+.0} {unit}", NAMES[i], c * k)
            })
            .collect();
        format!(
            "{} alike in {minutes:.0} min, the path cannot tell which: {}",
            alike_names(d),
            each.join(", ")
        )
    };
    if let Some(r) = d.temperature_correlation.filter(|r| r.abs() >= FOLLOWS) {
        let _ = write!(s, ", follows {temp_name} (r = {r:.2})");
    }
    if d.alike > 0 {
        let _ = write!(s, "; {} other parameters explain it alike", d.alike);
    }
    s
}

/// Factor from mm or rad to the unit a drift is told in, and that unit.
fn scaled_unit(param: usize) -> (f64, &'static str) {
    match unit(param) {
        Unit::Mm => (1e3, "µm"),
        Unit::Rad => (1e6, "µrad"),
    }
}

/// "l1..l5" when a drift's alike candidates are every rod, else their names, the best first:
/// "l3 or l1", "l3, l1 or l5".
fn alike_names(d: &Drift) -> String {
    let mut named: Vec<usize> = d.named().map(|(i, _)| i).collect();
    named.sort_unstable();
    let mut rods: Vec<usize> = rpkm_core::params::RODS.iter().map(|r| r.l).collect();
    rods.sort_unstable();
    if named == rods {
        return "l1..l5".to_owned();
    }
    let mut names: Vec<String> = d.named().map(|(i, _)| NAMES[i].to_owned()).collect();
    names[1..].sort_unstable();
    or_list(&names)
}

/// What an engineer can check of a candidate: the F-test, its parameters, the covariate
/// the residual follows, the held-out RMS before and after, and what the search made of it.
pub fn evidence(c: &Candidate) -> String {
    let mut s = format!(
        "chi2/dof {:.2} -> {:.2}, F = {:.1} ({}); {}",
        c.chi2_per_dof_before,
        c.chi2_per_dof_after,
        c.f_statistic,
        p_is(c.p_value),
        values(&c.params)
    );
    if let Some(f) = &c.follows {
        let _ = write!(s, "; {}", follows(f));
    }
    for p in [c.prediction, c.cross_validated].into_iter().flatten() {
        let _ = write!(s, "; {}", prediction(&p));
        if p.worse && c.significant && c.relevant {
            s.push_str(": fits the campaign, predicts worse: it absorbs something else");
        }
    }
    if c.prediction.is_none() {
        if let (Some(b), Some(a)) = (c.val_rms_before, c.val_rms_after) {
            let (b, a) = (um_from_mm(b), um_from_mm(a));
            let _ = write!(s, "; held-out RMS as measured {b:.1} -> {a:.1} µm");
        }
    }
    let _ = write!(s, "{}", judged(&c.judged));
    s
}

/// The effect parameters identified, with their σ (three at most), then those not fitted
/// with the reason.
fn values(params: &[rpkm_core::calib::EffectEstimate]) -> String {
    let mut shown: Vec<String> = params
        .iter()
        .filter(|e| e.identified && e.physical())
        .take(3)
        .map(|e| format!("{} = {}", e.name, with_sigma(e.value, e.sigma, &e.unit)))
        .collect();
    shown.extend(held(params));
    shown.join(", ")
}

/// "thermal_lag:rods: 9 rate_error_* terms of this campaign (K/s), each held near zero by its
/// prior, fitted at 1.2x their priors (RMS); not the machine's, not listed".
pub fn anchored(a: &rpkm_core::calib::AnchoredTerms) -> String {
    format!(
        "{}: {} {}* terms of this campaign ({}), each held near zero by its prior, fitted at \
         {:.1}x their priors (RMS); not the machine's, not listed",
        a.effect, a.terms, a.stem, a.unit, a.over_prior
    )
}

/// "tau not fitted: no sensitivity at its start 0 s (...)", per effect parameter not fitted.
pub fn held(params: &[rpkm_core::calib::EffectEstimate]) -> Vec<String> {
    params
        .iter()
        .filter(|e| e.physical())
        .filter_map(|e| {
            e.held
                .as_ref()
                .map(|why| format!("{} not fitted: {why}", e.name))
        })
        .collect()
}

/// The judgement's words where they add to the figures: the evidence of both campaigns,
/// and why an addition that stood out was not named.
fn judged(j: &Judged) -> String {
    let size = j.size.map_or(String::new(), |v| {
        format!("explains {v:.2} of the noise's RMS")
    });
    let why = match j.outcome {
        Outcome::TooSmall => format!(": statistically detectable, too small to matter ({size})"),
        Outcome::Implausible => format!(
            ": implausible values, it absorbs something else ({})",
            j.implausible.join("; ")
        ),
        Outcome::Contradicted => ": the held-out data contradict it".to_owned(),
        Outcome::Incomplete => {
            ": it leaves out a part or effect that earns its place (a larger model beats it)"
                .to_owned()
        }
        Outcome::MemberAddsNothing => {
            ": one of its effects adds nothing to the prediction of the others".to_owned()
        }
        Outcome::SimplerNamed => ": predicts as well as a simpler model, which is named".to_owned(),
        Outcome::OutdoneByTerm => {
            ": a dictionary term explains as much, and the residual stays structured".to_owned()
        }
        _ => String::new(),
    };
    format!(
        "; {} {}{why}",
        evidence_of(j.evidence_of),
        p_is(j.evidence_p)
    )
}

/// What an addition's evidence combines, in words: both campaigns only where a held-out one
/// was given.
fn evidence_of(e: EvidenceOf) -> &'static str {
    match e {
        EvidenceOf::FitAndHeldOut => "evidence of both campaigns (fit and held-out prediction)",
        EvidenceOf::FitAndCrossValidation => {
            "evidence of the campaign (fit and cross-validation by setup; no held-out campaign \
             decided)"
        }
        EvidenceOf::FitAlone => "evidence of the fit alone (nothing predicted)",
    }
}

/// A model of the search in words: "thermal:rods + preload_elastic: F = 98.0 (p = 1e-40);
/// alpha_rods = ...; held-out RMS 9.14 -> 4.60 µm (± 0.4); evidence ...".
pub fn trial(t: &ModelTrial) -> String {
    let added: Vec<String> = t.added.iter().map(|a| with_parts(a)).collect();
    // a model that fits a family of the current model with other parts says which
    let instead = t.instead.as_ref().map_or(String::new(), |v| {
        format!(
            ", with the model's {} as {v}",
            rpkm_core::effects::family_of(v)
        )
    });
    // the p-value is the larger of the F-test's and the Wald test's: where the Wald test
    // sets it, a large F beside a large p says the parameters trade off
    let wald = if t.wald_p > t.f_p {
        format!(
            ": the Wald test of its added parameters themselves, which trade off; the F-test's \
             own {}",
            p_is(t.f_p)
        )
    } else {
        String::new()
    };
    let mut s = format!(
        "{}{instead}: F = {:.1} ({}{wald}); {}",
        added.join(" + "),
        t.f_statistic,
        p_is(t.p_value),
        values(&t.params)
    );
    if let Some(p) = &t.prediction {
        let _ = write!(s, "; {}", prediction(p));
    }
    s.push_str(&judged(&t.judged));
    s
}

/// An effect's name with the parts it holds where a family is named whole: "thermal (all its
/// parts: rods+frame+scales)"; a part or an effect without parts as it is.
pub fn with_parts(name: &str) -> String {
    if name.contains(':') {
        return name.to_owned();
    }
    let parts = rpkm_core::effects::by_name(name)
        .map(|e| e.parts())
        .unwrap_or_default();
    if parts.len() > 1 {
        format!("{name} (all its parts: {})", parts.join("+"))
    } else {
        name.to_owned()
    }
}

/// "the kgm along residual follows a 60.0 mm period of carrier 4 (amplitude 2.40 µm, 85 % of
/// its variance, p = 9.5e-56)"; carriers that move together on these rows named together
/// ("of carrier 1 or 4 (they move together on the self-calibration lines: ...)"), and the
/// stronger periods passed over as aliases of a dictionary term said so.
pub fn periodic(p: &Periodic) -> String {
    let (scale, unit) = if p.direction.starts_with("psi") {
        (1e6, "µrad")
    } else {
        (1e3, "µm")
    };
    let carriers: Vec<String> = std::iter::once(p.carrier)
        .chain(p.tied.iter().map(|t| t.carrier))
        .map(|c| c.to_string())
        .collect();
    let tie = if p.tied.is_empty() {
        String::new()
    } else {
        let pitches: Vec<String> = p
            .tied
            .iter()
            .filter(|t| (t.pitch_mm / p.pitch_mm - 1.0).abs() > 0.01)
            .map(|t| format!("{:.1} mm in carrier {}'s position", t.pitch_mm, t.carrier))
            .collect();
        format!(
            "they move together on {}, so the residual cannot tell whose period it is{}; ",
            setups_of(&p.instrument),
            if pitches.is_empty() {
                String::new()
            } else {
                format!(" ({})", pitches.join(", "))
            }
        )
    };
    let mut s = format!(
        "the {} {} residual follows a {:.1} mm period of carrier {} ({tie}amplitude {:.2} \
         {unit}, {:.0} % of its variance, p = {:.1e})",
        p.instrument,
        p.direction,
        p.pitch_mm,
        or_list(&carriers),
        p.amplitude * scale,
        100.0 * p.explained,
        p.p_value
    );
    let aliases: Vec<String> = p
        .aliases
        .iter()
        .map(|a| {
            format!(
                "a {:.1} mm period of carrier {} in the {} {} residual follows {}",
                a.pitch_mm, a.carrier, a.instrument, a.direction, a.term
            )
        })
        .collect();
    if !aliases.is_empty() {
        let _ = write!(
            s,
            "; passed over as aliases, not periods of their own: {}",
            aliases.join(", ")
        );
    }
    s
}

/// "4", "4 or 1", "4, 1 or 2".
fn or_list(items: &[String]) -> String {
    match items.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => items.concat(),
    }
}

/// Where an instrument's rows were taken, for "they move together on ...".
fn setups_of(instrument: &str) -> &'static str {
    match instrument {
        "self" => "the self-calibration lines",
        "kgm" => "the grid encoder's squares",
        "lt" => "the laser tracker's poses",
        "dbb" => "the ball-bar's circles",
        "li_x" | "li_y" => "the interferometer's lines",
        "li_psi" => "the angle optics' lines",
        _ => "these poses",
    }
}

/// "neighbours along the kgm along paths are alike (autocorrelation 0.62, z = 7.1)".
pub fn neighbours(n: &Neighbours) -> String {
    format!(
        "neighbouring poses of the {} {} residual are alike along the setups' paths \
         (autocorrelation {:.2}, {:.1} standard deviations above shuffled, p = {:.1e})",
        n.instrument, n.direction, n.autocorrelation, n.z_score, n.p_value
    )
}

/// What a structured residual shows, of the three tests, where each found structure.
fn structure_found(d: &ModelDiagnosis) -> Vec<String> {
    let level = d.test.dictionary_level;
    let mut found = Vec::new();
    if let Some(u) = &d.unexplained {
        found.push(follows(u));
    }
    if let Some(p) = d.periodic.as_ref().filter(|p| p.p_value < level) {
        found.push(periodic(p));
    }
    if let Some(n) = d.neighbours.as_ref().filter(|n| n.p_value < level) {
        found.push(neighbours(n));
    }
    found
}

/// The verdict in one sentence: the missing effect and its evidence, the structure no effect
/// explains (in the calibration campaign, or in the held-out data only), or that nothing is
/// missing; the noise groups off their rating appended.
pub fn verdict(d: &ModelDiagnosis) -> String {
    let model = if d.model_effects.is_empty() {
        "the geometric model".to_owned()
    } else {
        format!("the model with {}", d.model_effects.join(", "))
    };
    let noise_words = noise(&d.noise_groups);
    // what every verdict ends with: a family the campaigns do not decide, then the noise
    let undecided = d.undecided.iter().fold(String::new(), |mut s, u| {
        let _ = write!(s, "; {}", undecided_short(u));
        s
    });
    let tail = if noise_words.is_empty() {
        undecided
    } else {
        format!("{undecided}; noise: {noise_words}")
    };
    let remains = d
        .unexplained
        .as_ref()
        .map_or(String::new(), |u| format!("; what remains: {}", follows(u)));
    let tied = d.tied_term.as_ref().map_or(String::new(), |t| {
        format!("; the dictionary term {t} follows the residual as well, but a term cannot predict held-out poses")
    });
    let held = d.held_out.as_ref();
    let carried = d.carried.as_ref().map_or(String::new(), carried_words);
    match d.verdict_kind {
        VerdictKind::MissingEffect => {
            // what was found, parts and all: `--effects thermal` would fit every part of
            // the family in rpkm calibrate, not the ones the search chose
            let add = d.missing_effects.join(",");
            let resettled = d.resettled.as_ref().map_or(String::new(), |r| {
                format!(
                    ", with the model's {} fitted as {r} (the next diagnosis settles its parts \
                     again)",
                    rpkm_core::effects::family_of(r)
                )
            });
            format!(
                "missing effect: {}{resettled} ({}){tied}{remains}; add --effects {add}{tail}",
                d.missing_effects.join(" with "),
                named_evidence(d)
            )
        }
        VerdictKind::UnexplainedStructure
            if held.is_some_and(|h| !h.agrees()) && !cal_structured(d) =>
        {
            format!(
                "{model} explains the calibration campaign but not the held-out data: {}; no \
                 effect tried predicts them better{tail}",
                held.map(held_out).unwrap_or_default()
            )
        }
        VerdictKind::UnexplainedStructure => {
            let why = d.candidates.first().map_or(String::new(), |c| {
                format!(
                    " (the best, {}, p = {:.1e}, BIC gain {:.1})",
                    c.effect, c.p_value, c.bic_gain
                )
            });
            let found = structure_found(d);
            format!(
                "{model} leaves a structured residual that no effect of the library explains{why}; {}{carried}{tail}",
                if found.is_empty() {
                    "no covariate, force, time or workspace term follows it".to_owned()
                } else {
                    found.join("; ")
                }
            )
        }
        VerdictKind::NothingMissing => {
            let doubt = noisier_words(d);
            let agree = held.map_or(String::new(), |h| format!("; {}", held_out(h)));
            format!(
                "nothing is missing that the tests can find: {model} explains the measurements \
                 to their noise (no effect, dictionary term, period or neighbour structure is \
                 significant; chi2/dof {:.2} at the estimated noise){carried}{agree}{tail}{doubt}",
                d.chi2_per_dof
            )
        }
    }
}

/// What the structure tests read without: the part of the residual the thermometers' noise
/// makes through the model's lag.
fn carried_words(c: &Carried) -> String {
    let columns: Vec<String> = c
        .columns
        .iter()
        .map(|(name, terms)| format!("{name}: {terms} smooth terms in time"))
        .collect();
    format!(
        "; the residual read without what the thermometer's noise makes through the lag ({}, {:.1} % of its chi2)",
        columns.join(", "),
        100.0 * c.share
    )
}

/// Whether the calibration campaign's residual itself is structured (the verdict's own
/// tests, at their level).
fn cal_structured(d: &ModelDiagnosis) -> bool {
    let level = d.test.dictionary_level;
    d.structure.p_value < level
        || d.periodic.as_ref().is_some_and(|p| p.p_value < level)
        || d.neighbours.as_ref().is_some_and(|n| n.p_value < level)
}

/// The evidence of the model named: its candidate's where it is one effect, else the
/// search's trial of the combination.
fn named_evidence(d: &ModelDiagnosis) -> String {
    let single = d.resettled.is_none();
    if let ([one], true) = (d.missing_effects.as_slice(), single) {
        if let Some(c) = d.candidates.iter().find(|c| &c.effect == one) {
            return evidence(c);
        }
    }
    d.trials
        .iter()
        .find(|t| {
            t.added.iter().all(|a| d.missing_effects.contains(a))
                && t.added.len() == d.missing_effects.len()
                && t.instead == d.resettled
        })
        .map(trial)
        .unwrap_or_default()
}

/// "; encoder more than twice its rating: either ..." for the groups estimated above twice
/// their rating (the ratios themselves are in the noise words before it).
fn noisier_words(d: &ModelDiagnosis) -> String {
    if d.noisier_than_rated.is_empty() {
        return String::new();
    }
    let groups: Vec<&str> = d
        .noisier_than_rated
        .iter()
        .map(|n| n.group.as_str())
        .collect();
    format!(
        "; {} more than twice its rating: either the instrument is that noisy, or something \
         is missing that shows as noise",
        groups.join(", ")
    )
}

/// Why a diagnosis's model is not the one `rpkm calibrate`, `rpkm plan` and the nodes default
/// to (model 29), when it is not: model 24 holds rod 5 to rod 4 so that the imperfect
/// parallel-holder, rod 5's own five parameters, is a candidate tested like any other effect.
pub fn model_choice(d: &ModelDiagnosis) -> Option<String> {
    let freed = d
        .effects_in_model
        .iter()
        .any(|e| Family::of(e) == Some(Family::Parallelogram));
    (d.model == Model::M24 && !freed).then(|| {
        "model 24, where rpkm calibrate, rpkm plan and the nodes default to model 29: the \
         diagnosis holds rod 5 parallel to rod 4 so that the imperfect parallel-holder (rod 5's \
         five parameters, model 29) is tested as a candidate, `parallelogram`, like any other \
         effect; where it is named, calibrate with --model 29 (--model 29 starts the \
         diagnosis there)"
            .to_owned()
    })
}

/// How the verdict was tested, in one sentence.
pub fn test(t: &Test) -> String {
    format!(
        "noise levels estimated per group from the campaign ({} rounds); candidates, each part \
         of a family and pairs by their evidence (the nested F-test combined with the \
         prediction of the held-out campaign, or of left-out setups where none decides) at level {:.2e} (Bonferroni over {}), named when they \
         predict better by more than a fifth of the noise, with physical values, the simplest \
         within one standard error of the best; dictionary, periodogram and neighbour tests \
         each at level {:.2e} (n = {} rows); held-out data against the model's floor at level \
         {:.1e}",
        t.noise_rounds,
        t.candidate_level,
        t.candidates_tried,
        t.dictionary_level,
        t.rows,
        t.held_out_level
    )
}

/// The diagnosis as the `--json` file has it: the core's figures, and the sentences beside
/// them (`verdict`, `test`, each candidate's `evidence`; the test's figures are in
/// `test_settings`).
pub fn diagnosis_json(d: &ModelDiagnosis) -> serde_json::Result<serde_json::Value> {
    let mut v = serde_json::to_value(d)?;
    v["verdict"] = verdict(d).into();
    if let Some(why) = model_choice(d) {
        v["model_choice"] = why.into();
    }
    v["test_settings"] = serde_json::to_value(d.test)?;
    v["test"] = test(&d.test).into();
    if let Some(cands) = v["candidates"].as_array_mut() {
        for (json, c) in cands.iter_mut().zip(&d.candidates) {
            json["evidence"] = evidence(c).into();
        }
    }
    if let Some(trials) = v["trials"].as_array_mut() {
        for (json, t) in trials.iter_mut().zip(&d.trials) {
            json["evidence"] = trial(t).into();
        }
    }
    if let Some(h) = &d.held_out {
        v["held_out"]["judge"] = held_out(h).into();
    }
    Ok(v)
}

/// A setup's return to its reset pose, judged: "lt setup 3 moved 9.2 µm during 450 s
/// (1.2 µm/min; x +1.0 ± 27, y +9.1 ± 7.1 µm; p = 0.003): more than its noise" or "lt setup
/// 3 returned within its noise after 132 s (...)".
pub fn return_drift(d: &rpkm_core::returns::ReturnDrift) -> String {
    let parts: Vec<String> = d
        .components
        .iter()
        .map(|c| format!("{} {}", c.coordinate, um_with_sigma(c.value_mm, c.sigma_mm)))
        .collect();
    let detail = format!(
        "{:.1} µm/min; {} µm; p = {:.2e}",
        d.rate_mm_per_s * 60e3,
        parts.join(", "),
        d.p_value
    );
    if d.moved() {
        format!(
            "{} setup {} moved {:.1} µm during {:.0} s ({detail}): more than its noise, the \
             instrument drifted after its zero (line {})",
            d.instrument,
            d.setup,
            um_from_mm(d.magnitude_mm),
            d.seconds,
            d.line
        )
    } else {
        format!(
            "{} setup {} returned within its noise after {:.0} s ({:.1} µm; {detail})",
            d.instrument,
            d.setup,
            d.seconds,
            um_from_mm(d.magnitude_mm)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The drift WARN's words: one rod with its change and rate only where the path names it
    /// alone; else every rod that explains it alike with the change each would need and no
    /// rate ("l1..l5" for all five); "follows" only from FOLLOWS on; the other parameters
    /// alike counted.
    #[test]
    fn a_drift_in_words() {
        let index = |n: &str| rpkm_core::params::index_of(n).expect("rod");
        let mut d = Drift {
            param: index("l3"),
            margin: 1.001,
            candidates_alike: [None; rpkm_core::params::N_PARAMS],
            rate: 0.0118,
            rate_sigma: 0.0009,
            input: DriftInput::Temperature(20.4),
            change: 0.0193,
            over_s: 136.0,
            explained: 0.91,
            alike: 22,
            temperature_correlation: Some(0.87),
        };
        for (rod, c) in [
            ("l1", 0.015),
            ("l2", -0.0193),
            ("l3", 0.0193),
            ("l4", -0.0059),
            ("l5", 0.0097),
        ] {
            d.candidates_alike[index(rod)] = Some(c);
        }
        assert_eq!(
            drift(&d, "temp_machine"),
            "l1..l5 alike in 2 min, the path cannot tell which: l3 +19 µm, l1 +15 µm, \
             l2 -19 µm, l4 -6 µm, l5 +10 µm; 22 other parameters explain it alike"
        );
        d.candidates_alike[index("l2")] = None;
        d.candidates_alike[index("l4")] = None;
        d.candidates_alike[index("l5")] = None;
        assert!(
            drift(&d, "temp_machine").starts_with("l3 or l1 alike in 2 min"),
            "{}",
            drift(&d, "temp_machine")
        );
        d.candidates_alike[index("l1")] = None;
        d.margin = 1.8;
        d.alike = 0;
        d.temperature_correlation = Some(0.95);
        assert_eq!(
            drift(&d, "temp_machine"),
            "l3 +19 µm in 2 min (+11.80 ± 0.90 µm/K), follows temp_machine (r = 0.95)"
        );
    }

    /// A model of the search that fits a family of the current model with other parts says
    /// which: two such models of one added effect are no longer the same line.
    #[test]
    fn a_model_with_a_family_refitted_says_its_parts() {
        let trial = |instead: Option<&str>| {
            trial(&ModelTrial {
                added: vec!["encoder_scale".to_owned()],
                instead: instead.map(str::to_owned),
                k: 2.0,
                f_statistic: 97.9,
                p_value: 2.4e-13,
                wald_p: 2.4e-13,
                f_p: 2.1e-44,
                chi2_per_dof_after: 0.9,
                prediction: None,
                params: Vec::new(),
                judged: rpkm_core::diagnose::Judged {
                    evidence_p: 8.8e-18,
                    evidence_of: rpkm_core::diagnose::EvidenceOf::FitAlone,
                    size: Some(0.4),
                    matters: true,
                    implausible: Vec::new(),
                    outcome: rpkm_core::diagnose::Outcome::Outpredicted,
                },
            })
        };
        assert!(
            trial(None).starts_with("encoder_scale: F = 97.9"),
            "{}",
            trial(None)
        );
        let swapped = trial(Some("thermal:frame+scales"));
        assert!(
            swapped.starts_with(
                "encoder_scale, with the model's thermal as thermal:frame+scales: F = 97.9"
            ),
            "{swapped}"
        );
    }
}
