//! The tolerance prior's options (`--tolerance-mm`, `--tolerance-mrad`), shared by the
//! commands that calibrate under it (`rpkm calibrate`, `rpkm plan`).

use super::bad_input;
use rpkm_core::calib::Prior;
use rpkm_core::units::rad_from_mrad;

/// The manufacturing tolerances the calibration holds each parameter near its nominal value
/// with.
#[derive(clap::Args, Debug, Clone)]
pub struct PriorArgs {
    /// Manufacturing tolerance of the lengths (mm, one σ): what the campaign leaves
    /// unmeasured stays this uncertain.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance_mm: f64,
    /// Manufacturing tolerance of the angles (mrad, one σ).
    #[arg(long, default_value_t = 1.0)]
    pub tolerance_mrad: f64,
}

impl PriorArgs {
    /// The prior, each tolerance checked positive (bad input otherwise).
    pub fn prior(&self) -> anyhow::Result<Prior> {
        Ok(Prior {
            length_mm: positive("--tolerance-mm", self.tolerance_mm)?,
            angle_rad: rad_from_mrad(positive("--tolerance-mrad", self.tolerance_mrad)?),
        })
    }
}

/// `v` where it is a positive finite number; else bad input naming `flag`.
pub fn positive(flag: &str, v: f64) -> anyhow::Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(bad_input(format!("{flag} {v}: expected a positive number")))
    }
}
