//! `rpkm diagnose`: where the model fails, which physical effect is missing, and the held-out
//! error once it is added. Physics in `rpkm_core::diagnose`; here the terminal summary, the
//! JSON and the HTML report.

use super::effect_stages::{offered, parse_effects, read_effects_file, with_named_effect};
use super::summary::{print_summary, print_written, write_report};
use super::{bad_input, read_campaign, write_json};
use anyhow::Context;
use rpkm_core::diagnose::{self, held_out::coverage, DiagnosisOptions};
use rpkm_core::effects::Effect;
use rpkm_core::params::Model;
use rpkm_core::units::rad_from_mrad;
use rpkm_nodes::effects_file::{self};
use std::path::PathBuf;

/// The diagnosis's JSON with its `points` (left empty in `value`) serialised one point at a
/// time, as `value` would hold them: the same text.
struct Streamed<'a> {
    value: &'a serde_json::Value,
    points: &'a [diagnose::ResidualPoint],
}

impl serde::Serialize for Streamed<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let serde_json::Value::Object(map) = self.value else {
            return self.value.serialize(s);
        };
        let mut out = s.serialize_map(Some(map.len()))?;
        for (key, value) in map {
            if key == "points" {
                out.serialize_entry(key, &Points(self.points))?;
            } else {
                out.serialize_entry(key, value)?;
            }
        }
        out.end()
    }
}

/// Residual points serialised each through its JSON value (the keys in the order a value
/// holds them).
struct Points<'a>(&'a [diagnose::ResidualPoint]);

impl serde::Serialize for Points<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{Error, SerializeSeq};
        let mut seq = s.serialize_seq(Some(self.0.len()))?;
        for p in self.0 {
            seq.serialize_element(&serde_json::to_value(p).map_err(S::Error::custom)?)?;
        }
        seq.end()
    }
}

/// Find the physical effect the model is missing.
///
/// 1. Calibrates the current model (geometry, plus the effects given with --effects) and tests
///    its residual against the instruments' noise (chi-square).
/// 2. Tries every effect of the library not yet in the model (listed below; one beside a
///    family is tried where that family is in the model); for each, its parameters, a
///    nested F-test, the fraction of the residual above the noise it explains and the
///    held-out RMS after adding it. Ranked best first (BIC). A family's parts
///    (thermal:rods) and an effect's refinements (preload_elastic:rod3, a rod of another
///    stiffness with a compliance of its own) are tried where the family or effect stands
///    out, and the model is chosen whole.
/// 3. Names the missing effect, or says that nothing is missing.
/// 4. When a structured residual remains that no effect explains, points at the covariate,
///    drive force, time or workspace term it follows.
///
/// Then add the named effect and diagnose again: the next one, or "nothing is missing".
///
/// Example:
///   rpkm diagnose campaign.csv --model 24 --validate held_out.csv --report diag/
///   rpkm diagnose campaign.csv --effects thermal --validate held_out.csv --json d.json
#[derive(clap::Args, Debug)]
#[command(after_help = super::library_help::library())]
pub struct DiagnoseArgs {
    /// Campaign CSV (spec format); covariates such as temp_machine are used by the effects.
    pub campaign: PathBuf,
    /// Geometric model: 24 (rod 5 tied to rod 4: a perfect parallel-holder) or 29.
    #[arg(long, default_value_t = 24)]
    pub model: u32,
    /// Effects already in the model, comma-separated (e.g. thermal,preload_elastic): the
    /// library's, or those of --effects-file. A family's parts are pinned with `:` and `+`
    /// (thermal:rods, thermal:rods+frame), as the verdict's advice names them.
    #[arg(long, default_value = "")]
    pub effects: String,
    /// Effects written as data (YAML: name, summary, params with unit and prior, expressions
    /// of dq1..dq4, dx, dy, dpsi, dp.NAME; docs/effects.md): tried as candidates beside the
    /// library's, and named by --effects. Example:
    ///   rpkm diagnose c.csv --effects-file mine.yaml --validate v.csv
    #[arg(long)]
    pub effects_file: Option<PathBuf>,
    /// Held-out campaign: the RMS before and after each candidate, and the noise floor.
    #[arg(long)]
    pub validate: Option<PathBuf>,
    /// Write the diagnosis as JSON (`missing_effect`, `baseline`, `candidates`, ...).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the report into this folder: report.html (one self-contained page: verdict,
    /// residual maps before and after adding the named effect, error vectors, noise) and
    /// report.json (the numbers behind the error-vector maps).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Significance level of the tests.
    #[arg(long, default_value_t = 0.001)]
    pub alpha: f64,
    /// The instruments' stated noise, NAME=VALUE comma-separated or a YAML file (mm, rad for
    /// psi): lt (isotropic tracker), lt_along, lt_across, lt_across_per_m, kgm, dbb, li, psi,
    /// encoder, force (N, drive forces), drive_position (the encoders in the force rows),
    /// tracker_x, tracker_y. Only the start of the estimation and the rating the
    /// estimates are compared with: the verdict does not hinge on it.
    #[arg(long)]
    pub noise: Option<String>,
    /// Manufacturing tolerances of the lengths (mm) and angles (mrad), one σ: the prior of
    /// the calibration.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance_mm: f64,
    #[arg(long, default_value_t = 1.0)]
    pub tolerance_mrad: f64,
    /// Threads the candidate effects are fitted on (0: every core). The diagnosis is the
    /// same, to the bit, whatever the number.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Fit every candidate effect to convergence instead of screening it first (by default
    /// each takes one Gauss-Newton step from the current model's fit, and only one that may
    /// be significant, p < 0.05, is fitted to convergence). The same verdict, slower; the
    /// candidates' figures then come from converged fits. Example:
    /// rpkm diagnose cal.csv --validate val.csv --no-screen
    #[arg(long)]
    pub no_screen: bool,
}

pub fn run(args: &DiagnoseArgs) -> anyhow::Result<()> {
    let model = Model::from_number(args.model)
        .ok_or_else(|| bad_input(format!("--model {}: expected 24 or 29", args.model)))?;
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        return Err(bad_input(format!(
            "--alpha {}: expected 0 < alpha < 1",
            args.alpha
        )));
    }
    let campaign = read_campaign(&args.campaign)?;
    let validation = args.validate.as_deref().map(read_campaign).transpose()?;
    let file = read_effects_file(
        args.effects_file.as_deref(),
        &[Some(&campaign), validation.as_ref()],
    )?;
    let in_model = parse_effects(&args.effects, file.as_ref())?;
    let refs: Vec<&dyn Effect> = in_model.iter().map(std::convert::AsRef::as_ref).collect();
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !(positive(args.tolerance_mm) && positive(args.tolerance_mrad)) {
        return Err(bad_input(
            "--tolerance-mm/--tolerance-mrad: expected positive numbers".to_owned(),
        ));
    }
    let opts = DiagnosisOptions {
        model,
        alpha: args.alpha,
        noise: super::parse_noise(args.noise.as_deref())?,
        prior: rpkm_core::calib::Prior {
            length_mm: args.tolerance_mm,
            angle_rad: rad_from_mrad(args.tolerance_mrad),
        },
        threads: args.threads,
        screen: !args.no_screen,
        ..Default::default()
    };
    let offer = offered(file.as_ref(), &refs);
    let mut d = diagnose::diagnose_among(&campaign, validation.as_ref(), &refs, &offer, &opts)
        .with_context(|| format!("diagnosing {}", args.campaign.display()))?;
    print_summary(&campaign, validation.as_ref(), &d);
    if let Some(f) = &file {
        print_written(f);
    }
    if let Some(path) = &args.json {
        // the residual points (one per row: 2·10⁵ on 10⁵ poses) are written one at a time,
        // not held as one JSON tree beside the diagnosis (110 MB there, the process's peak)
        let points = std::mem::take(&mut d.points);
        let mut json = rpkm_nodes::words::diagnosis_json(&d)?;
        d.points = points;
        if let Some(f) = &file {
            json["effects_file"] = effects_file::to_json(f);
        }
        if let Some(v) = &validation {
            json["held_out_coverage"] = serde_json::to_value(coverage::coverage(&campaign, v))?;
            if let Some(h) = &d.held_out {
                json["held_out_poses"] = super::held_out_poses::held_out_poses(v, h)?;
            }
        }
        if let Some(mib) = super::peak_resident_mib() {
            // the process's own high-water mark so far (`rpkm bench calibration` reads it)
            json["peak_resident_mib"] = serde_json::json!(mib);
        }
        write_json(
            path,
            &Streamed {
                value: &json,
                points: &d.points,
            },
        )?;
        println!("\nwrote {}", path.display());
    }
    if let Some(dir) = &args.report {
        let after = with_named_effect(&campaign, validation.as_ref(), (&refs, &offer), &opts, &d)?;
        let page = write_report(
            dir,
            "rpkm diagnose",
            (&campaign, validation.as_ref()),
            &d,
            after.as_ref(),
            (None, effects_file::expressions(file.as_ref())),
        )?;
        println!("report: {}", page.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::Streamed;
    use rpkm_core::diagnose::ResidualPoint;

    /// The JSON with its points streamed is the text of the whole value, to the byte: keys
    /// before and after `points`, the points' keys in a value's order (not the struct's).
    #[test]
    fn streamed_points_write_the_whole_value() {
        let points: Vec<ResidualPoint> = (0..3)
            .map(|i| ResidualPoint {
                pose: i,
                line: 10 + i,
                instrument: "self".to_owned(),
                direction: format!("q{}", i + 2),
                x: -32.608_867_535_693_66 * i as f64,
                y: 899.727_930_355_682_1,
                t: 1e-300,
                value: -1.308_397_666_207_383_7,
                sigma: 0.1 + 0.2,
            })
            .collect();
        let mut whole = serde_json::json!({
            "baseline": {"chi2": 1.5, "dof": 3},
            "peak_resident_mib": 359.2,
            "verdict_kind": "nothing_missing",
            "zz": [1, 2],
        });
        let mut holed = whole.clone();
        whole["points"] = serde_json::to_value(&points).expect("points");
        holed["points"] = serde_json::json!([]);
        let streamed = serde_json::to_string_pretty(&Streamed {
            value: &holed,
            points: &points,
        })
        .expect("streamed");
        assert_eq!(
            streamed,
            serde_json::to_string_pretty(&whole).expect("whole")
        );
        assert!(streamed.contains("\"direction\": \"q2\",\n      \"instrument\""));
    }
}
