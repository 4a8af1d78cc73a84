//! The effects a command takes (`--effects`, `--effects-file`) and the diagnosis again with
//! the named one added: what `rpkm diagnose`, `rpkm calibrate` and the demo share; and the
//! table of `rpkm calibrate --effects`, the model with its effects added one by one.

use super::bad_input;
use anyhow::Context;
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::{self, DiagnosisOptions, ModelDiagnosis};
use rpkm_core::effects::{self, Effect};
use rpkm_core::units::um_from_mm;
use rpkm_nodes::effects_file::{self, EffectsFile};
use std::path::Path;

/// Effects of a comma-separated list (the library's, or the file's), or a bad-input error
/// naming the option.
pub fn parse_effects(
    list: &str,
    file: Option<&EffectsFile>,
) -> anyhow::Result<Vec<Box<dyn Effect>>> {
    effects_file::parse_list(list, file).map_err(|e| bad_input(format!("--effects: {e}")))
}

/// The effects file of --effects-file, read and checked against the campaigns it will meet
/// (bad input, exit 2, naming its file, line and column).
pub fn read_effects_file(
    path: Option<&Path>,
    campaigns: &[Option<&Campaign>],
) -> anyhow::Result<Option<EffectsFile>> {
    let Some(path) = path else {
        return Ok(None);
    };
    let mut columns: Vec<String> = Vec::new();
    for c in campaigns.iter().flatten() {
        columns.extend(c.covariate_names.iter().cloned());
    }
    let file = effects_file::read(path, &columns).map_err(|e| bad_input(e.to_string()))?;
    for c in campaigns.iter().flatten() {
        file.check(c).map_err(|e| bad_input(e.to_string()))?;
    }
    Ok(Some(file))
}

/// The file's effects not in the model: the candidates it offers.
pub fn offered<'a>(file: Option<&'a EffectsFile>, in_model: &[&dyn Effect]) -> Vec<&'a dyn Effect> {
    file.map(EffectsFile::all)
        .unwrap_or_default()
        .into_iter()
        .filter(|e| !in_model.iter().any(|m| m.name() == e.name()))
        .collect()
}

/// The diagnosis with the effect `d` names added to the model (diagnosed again), if it names
/// one: the "after" of the report. `offered` are the written effects tried besides the
/// library (the named one may be one of them).
pub fn with_named_effect(
    campaign: &Campaign,
    validation: Option<&Campaign>,
    (in_model, offered): (&[&dyn Effect], &[&dyn Effect]),
    opts: &DiagnosisOptions,
    d: &ModelDiagnosis,
) -> anyhow::Result<Option<ModelDiagnosis>> {
    let Some(missing) = &d.missing_effect else {
        return Ok(None);
    };
    let from_library;
    let effect: &dyn Effect = if let Some(e) = offered.iter().copied().find(|e| e.name() == missing)
    {
        e
    } else {
        from_library = effects::by_name(missing)?;
        from_library.as_ref()
    };
    let mut with: Vec<&dyn Effect> = in_model.to_vec();
    with.push(effect);
    let rest: Vec<&dyn Effect> = offered
        .iter()
        .copied()
        .filter(|e| e.name() != missing)
        .collect();
    let after = diagnose::diagnose_among(campaign, validation, &with, &rest, opts)
        .with_context(|| format!("diagnosing with {missing} added"))?;
    Ok(Some(after))
}

/// One row of the effect-by-effect table.
#[derive(serde::Serialize)]
pub struct Stage {
    pub model: String,
    /// χ²/ν with the rows weighted by the table's one noise ([`Stages::chi2_under`]): each
    /// model under its own estimate would read about 1 on every row.
    pub chi2_per_dof: f64,
    /// χ²/ν at the stated noise (the instruments' ratings, --noise).
    pub chi2_per_dof_stated: f64,
    pub cal_rms_um: f64,
    pub val_rms_um: Option<f64>,
    /// The held-out RMS with each setup's zero removed (what a model can predict), µm.
    pub val_rms_relative_um: Option<f64>,
    pub effect_params: Vec<rpkm_core::calib::EffectEstimate>,
}

/// The effect-by-effect table of `rpkm calibrate --effects`: its rows, and the noise their χ²
/// are under (the one estimated with the last model, which holds every effect: the models
/// compare under it).
pub struct Stages {
    pub rows: Vec<Stage>,
    pub chi2_under: String,
    /// The last model as the data settle it, where that is not the effects as given
    /// (`preload_elastic` as `preload_elastic:rod3`).
    pub settled_as: Option<Vec<String>>,
}

impl Stages {
    /// The model with `effects` added one by one, each evaluated as the diagnosis evaluates
    /// its current model (noise estimated, tolerance prior, no outlier elimination: the same
    /// rows in every model).
    pub fn of(
        campaign: &Campaign,
        validation: Option<&Campaign>,
        effects: &[&dyn Effect],
        opts: &DiagnosisOptions,
    ) -> anyhow::Result<Stages> {
        let evaluated = (0..=effects.len())
            .map(|k| diagnose::evaluate(campaign, validation, &effects[..k], opts))
            .collect::<Result<Vec<_>, _>>()?;
        // one noise for every row, so that the χ² compare the models: the last model's
        let last = evaluated.last().map(|e| e.noise.model.clone());
        let given: Vec<String> = effects.iter().map(|e| e.name().to_owned()).collect();
        let settled_as = evaluated
            .last()
            .map(|e| e.model_effects.clone())
            .filter(|fitted| *fitted != given);
        let under = last.unwrap_or_else(|| opts.noise.clone());
        let rows = evaluated
            .into_iter()
            .enumerate()
            .map(|(k, e)| Stage {
                // as fitted: a family or an effect the data settle (thermal:rods)
                model: match (k, e.model_effects.get(k.saturating_sub(1))) {
                    (0, _) => format!("{}", opts.model),
                    (_, Some(fitted)) => format!("+ {fitted}"),
                    _ => format!("+ {}", effects[k - 1].name()),
                },
                chi2_per_dof: e.chi2_per_dof_under(&under),
                chi2_per_dof_stated: e.baseline.chi2_per_dof,
                cal_rms_um: um_from_mm(e.fit.cal_rms),
                val_rms_um: e.baseline.val_rms.map(um_from_mm),
                val_rms_relative_um: e.baseline.val_rms_relative.map(um_from_mm),
                effect_params: e.fit.effect_params,
            })
            .collect();
        let names: Vec<&str> = effects.iter().map(|e| e.name()).collect();
        Ok(Stages {
            rows,
            settled_as,
            chi2_under: format!(
                "the noise estimated with the last model, {} + {}",
                opts.model,
                names.join(" + ")
            ),
        })
    }

    /// The table, and the identified effect parameters of the last model.
    pub fn print(&self) {
        println!(
            "\nThe error effect by effect (chi2/dof: every model's rows weighted by one noise, {}; \
             the model that explains the data reads near 1):",
            self.chi2_under
        );
        println!(
            "  {:<24} {:>10} {:>10} {:>12} {:>12} {:>13}",
            "model", "chi2/dof", "at stated", "cal RMS µm", "held-out µm", "zero removed"
        );
        // the bar: the held-out error a model can predict (each setup's zero removed)
        let shown = |s: &Stage| s.val_rms_relative_um.or(s.val_rms_um);
        let top = self.rows.iter().filter_map(shown).fold(0.0, f64::max);
        let opt = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.1}"));
        for s in &self.rows {
            let bar = shown(s)
                .map(|v| "#".repeat(rpkm_core::convert::round_count(40.0 * v / top.max(1e-9))))
                .unwrap_or_default();
            println!(
                "  {:<24} {:>10.2} {:>10.2} {:>12.1} {:>12} {:>13} {bar}",
                s.model,
                s.chi2_per_dof,
                s.chi2_per_dof_stated,
                s.cal_rms_um,
                opt(s.val_rms_um),
                opt(s.val_rms_relative_um)
            );
        }
        if let Some(fitted) = &self.settled_as {
            println!(
                "  (the table's models as the data settle them; the calibration above fits the \
                 effects as given: --effects {} fits the settled model)",
                fitted.join(",")
            );
        }
        if let Some(last) = self.rows.last() {
            for e in last
                .effect_params
                .iter()
                .filter(|e| e.identified && e.physical())
            {
                println!(
                    "  {}.{} = {}",
                    e.effect,
                    e.name,
                    rpkm_nodes::words::with_sigma(e.value, e.sigma, &e.unit)
                );
            }
        }
    }

    /// The chart of the held-out and calibration RMS per stage (SVG).
    pub fn write_chart(&self, path: &Path) -> anyhow::Result<()> {
        let cats: Vec<String> = self.rows.iter().map(|s| s.model.clone()).collect();
        let svg = crate::plot::bar_chart(
            "Held-out TCP RMS per added effect",
            "RMS (µm)",
            &cats,
            &[
                (
                    "held-out".to_owned(),
                    self.rows
                        .iter()
                        .map(|s| s.val_rms_um.unwrap_or(f64::NAN))
                        .collect(),
                ),
                (
                    "calibration".to_owned(),
                    self.rows.iter().map(|s| s.cal_rms_um).collect(),
                ),
            ],
            &crate::plot::BarOptions::default(),
        );
        std::fs::write(path, svg)?;
        println!("  chart: {}", path.display());
        Ok(())
    }
}
