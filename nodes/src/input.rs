//! Reading the user's files (campaigns, parameter JSON), for the command line and the nodes:
//! every error is bad input ([`crate::error::bad_input`], exit 2) naming the file and, where
//! there is one, the line and column or byte.

use std::path::Path;

use rpkm_core::campaign::Campaign;
use rpkm_core::params::{self, Params};

use crate::error::bad_input;

/// Reads and parses a campaign file; errors name the file, line and column (or byte offset
/// for bytes that are not UTF-8).
pub fn read_campaign(path: &Path) -> anyhow::Result<Campaign> {
    let bytes = std::fs::read(path)
        .map_err(|e| bad_input(format!("{}: cannot read campaign: {e}", path.display())))?;
    Campaign::parse_bytes(&bytes, &path.display().to_string()).map_err(anyhow::Error::new)
}

/// Reads a parameter file: a JSON object mapping spec names to values (mm, rad), or the JSON
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
