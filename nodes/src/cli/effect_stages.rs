//! The effects a command takes (`--effects`, `--effects-file`) and the diagnosis again with
//! the named one added: what `rpkm diagnose`, `rpkm calibrate` and the demo share.

use super::bad_input;
use crate::effects_file::{self, EffectsFile};
use anyhow::Context;
use rpkm_core::campaign::Campaign;
use rpkm_core::diagnose::{self, Diagnosis, Options};
use rpkm_core::effects::{self, Effect};
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
    opts: &Options,
    d: &Diagnosis,
) -> anyhow::Result<Option<Diagnosis>> {
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
