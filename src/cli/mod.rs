//! Subcommands of the `rpkm` command line. Thin: parsing, files, printing; physics in rpkm_core.

pub mod analyze;
pub mod bag;
pub(crate) mod bag_files;
pub mod bench;
pub mod calibrate;
pub mod demo;
pub mod diagnose;
mod effect_stages;
mod held_out_poses;
pub mod history;
pub mod ingest;
pub mod library_help;
pub mod monitor;
pub mod plan;
pub mod preload;
mod prior_args;
pub mod record;
pub mod replay;
pub mod security;
pub mod simulate;
mod summary;
mod transport_args;

use anyhow::Context;
use std::path::Path;

// Errors, exit codes and file readers live below the command line, where the nodes use them
// too; re-exported so that every subcommand names them as `super::…`.
pub use rpkm_nodes::error::{bad_input, error_chain, exit_code, BadInput};
pub use rpkm_nodes::input::{read_campaign, read_params};

/// The noise model of `--noise`: `NAME=VALUE,...` or a YAML file of `NAME: VALUE` lines
/// (`.yaml`/`.yml`); the spec's figures for what it does not name.
pub fn parse_noise(spec: Option<&str>) -> anyhow::Result<rpkm_core::noise::NoiseModel> {
    let spec = spec.unwrap_or("").trim();
    let is_yaml = std::path::Path::new(spec)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("yaml") || e.eq_ignore_ascii_case("yml"));
    let text = if is_yaml {
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

/// Write pretty JSON to a file.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> anyhow::Result<()> {
    use std::io::Write;
    // written as it is serialised: the text of a 10⁵-pose diagnosis is 52 MB, held whole
    // it was the process's peak
    let file =
        std::fs::File::create(path).with_context(|| format!("writing {}", path.display()))?;
    let mut out = std::io::BufWriter::new(file);
    serde_json::to_writer_pretty(&mut out, value)
        .with_context(|| format!("writing {}", path.display()))?;
    out.flush()
        .with_context(|| format!("writing {}", path.display()))
}

/// The process's peak resident memory so far, MiB (`VmHWM` of /proc/self/status; None where
/// the system has none).
pub(crate) fn peak_resident_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb / 1024.0)
}
