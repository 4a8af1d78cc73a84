//! Subcommands of the `rpkm` command line. Thin: parsing, files, printing; physics in rpkm_core.

pub mod analyze;
pub mod bag;
pub mod bench;
pub mod calibrate;
pub mod demo;
pub mod diagnose;
pub mod ingest;
pub mod preload;
pub mod record;
pub mod replay;
pub mod simulate;
pub mod simulate_bag;

use anyhow::Context;
use rpkm_core::campaign::Campaign;
use rpkm_core::params::{self, Params};
use std::path::Path;

/// Bad input from the user (a file, an argument): the command exits with code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// An error that makes the command exit with code 2.
pub fn bad_input(msg: String) -> anyhow::Error {
    anyhow::Error::new(BadInput(msg))
}

/// The noise model of `--noise`: `NAME=VALUE,...` or a YAML file of `NAME: VALUE` lines
/// (`.yaml`/`.yml`); the spec's figures for what it does not name.
pub fn parse_noise(spec: Option<&str>) -> anyhow::Result<rpkm_core::noise::NoiseModel> {
    let spec = spec.unwrap_or("").trim();
    let text = if spec.ends_with(".yaml") || spec.ends_with(".yml") {
        let raw =
            std::fs::read_to_string(spec).map_err(|e| bad_input(format!("--noise {spec}: {e}")))?;
        let map: std::collections::BTreeMap<String, f64> = serde_yaml::from_str(&raw)
            .map_err(|e| bad_input(format!("--noise {spec}: expected NAME: VALUE lines: {e}")))?;
        map.iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect::<Vec<_>>()
            .join(",")
    } else {
        spec.to_owned()
    };
    rpkm_core::noise::NoiseModel::parse(&text).map_err(|e| bad_input(format!("--noise: {e}")))
}

/// The error and its causes joined by ": ", leaving out a cause whose text the message
/// before it already contains (errors that print their source inline).
pub fn error_chain(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let line = cause.to_string();
        if !text.contains(&line) {
            if !text.is_empty() {
                text.push_str(": ");
            }
            text.push_str(&line);
        }
    }
    text
}

/// Exit code of an error: 2 for bad input, 1 otherwise.
pub fn exit_code(e: &anyhow::Error) -> i32 {
    if e.chain()
        .any(|c| c.is::<BadInput>() || c.is::<rpkm_core::campaign::CampaignError>())
    {
        2
    } else {
        1
    }
}

/// Read and parse a campaign file; errors name the file, line and column.
pub fn read_campaign(path: &Path) -> anyhow::Result<Campaign> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| bad_input(format!("{}: cannot read campaign: {e}", path.display())))?;
    Campaign::parse(&text, &path.display().to_string()).map_err(anyhow::Error::new)
}

/// Read a parameter file: a JSON object mapping spec names to values (mm, rad), or the JSON
/// written by `rpkm calibrate` (its `parameters` object). Unnamed parameters stay nominal.
pub fn read_params(path: &Path) -> anyhow::Result<Params> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| bad_input(format!("{}: cannot read parameters: {e}", path.display())))?;
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        bad_input(format!(
            "{}:{}:{}: not JSON: {e}",
            path.display(),
            e.line(),
            e.column()
        ))
    })?;
    let obj = value
        .get("parameters")
        .unwrap_or(&value)
        .as_object()
        .ok_or_else(|| {
            bad_input(format!(
                "{}: expected a JSON object of parameter names to values",
                path.display()
            ))
        })?;
    let mut p = Params::nominal();
    for (name, v) in obj {
        let i = params::index_of(name)
            .ok_or_else(|| bad_input(format!("{}: unknown parameter `{name}`", path.display())))?;
        p[i] = v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
            bad_input(format!(
                "{}: parameter `{name}`: expected a finite number, found {v}",
                path.display()
            ))
        })?;
    }
    Ok(p)
}

/// Write pretty JSON to a file.
pub fn write_json(path: &Path, value: &serde_json::Value) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}
