//! Reading the user's files (campaigns, parameter JSON), for the command line and the nodes:
//! every error is bad input ([`crate::error::bad_input`], exit 2) naming the file and, where
//! there is one, the line and column or byte.

use std::path::Path;

use rpkm_core::campaign::Campaign;
use rpkm_core::params::{self, Params};

use crate::calibration_file::CalibrationFile;
use crate::error::bad_input;

/// Reads and parses a campaign file; errors name the file, line and column (or byte offset
/// for bytes that are not UTF-8).
pub fn read_campaign(path: &Path) -> anyhow::Result<Campaign> {
    let bytes = std::fs::read(path)
        .map_err(|e| bad_input(format!("{}: cannot read campaign: {e}", path.display())))?;
    let campaign =
        Campaign::parse_bytes(&bytes, &path.display().to_string()).map_err(anyhow::Error::new)?;
    check_readings(&campaign)?;
    Ok(campaign)
}

/// Largest distance, mm, between a TCP instrument's reading and where the nominal machine
/// puts the TCP at the row's actuator positions (relative to the setup's reset pose, as the
/// instrument measures). A real machine is within millimetres of its drawing (the spec's
/// tolerances are tenths of a millimetre to a few), so a reading 100 mm off measures
/// something else: a unit mix-up, another machine, a tracker that lost its target. The same
/// bound as the actuator positions' [`COMPATIBILITY_MAX_MM`](rpkm_core::campaign::plausible).
pub const READING_OFF_MAX_MM: f64 = rpkm_core::campaign::plausible::COMPATIBILITY_MAX_MM;

/// Every TCP reading of `campaign` within [`READING_OFF_MAX_MM`] of the nominal machine's
/// TCP: the plausibility of a reading, which a calibration campaign and a held-out one are
/// held to alike. A pose the nominal model cannot solve is left to the calibration, which
/// names it.
pub fn check_readings(campaign: &Campaign) -> anyhow::Result<()> {
    let Ok(errors) = rpkm_core::obs::tcp_errors(campaign, &Params::nominal(), params::Model::M24)
    else {
        return Ok(());
    };
    match errors.iter().find(|e| e.value.abs() > READING_OFF_MAX_MM) {
        None => Ok(()),
        Some(&rpkm_core::obs::TcpError {
            pose,
            direction: coordinate,
            value: off,
            ..
        }) => Err(bad_input(format!(
            "{}:{} ({coordinate}): the reading is {:.1} mm from where the machine puts the \
             TCP at this row's actuator positions, expected within {READING_OFF_MAX_MM} mm \
             (a unit mix-up, or a measurement of something else)",
            campaign.source,
            campaign.poses[pose].line,
            off.abs()
        ))),
    }
}

/// Reads a parameter file: a JSON object mapping spec names to values (mm, rad), or the JSON
/// written by `rpkm calibrate` (its `parameters` object, [`CalibrationFile`]). Unnamed
/// parameters stay nominal.
pub fn read_params(path: &Path) -> anyhow::Result<Params> {
    params_of(path, &CalibrationFile::read(path)?)
}

/// The parameters of `file` (read from `path`): each name a spec name, else bad input.
pub fn params_of(path: &Path, file: &CalibrationFile) -> anyhow::Result<Params> {
    let mut p = Params::nominal();
    for (name, v) in &file.parameters {
        let i = params::index_of(name)
            .ok_or_else(|| bad_input(format!("{}: unknown parameter `{name}`", path.display())))?;
        p[i] = *v;
    }
    Ok(p)
}
