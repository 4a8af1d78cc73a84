//! Actuator streams from the digital twin: what the drive interface would publish at the
//! control rate, for `rpkm simulate --stream-hz` (the reference stream and preload-fault bags).
//!
//! Per sample the twin's controller commands its igm of the target, the true machine settles
//! ([`Twin::machine_state`]: rigid with q2, q3 following, or elastic with all four drives
//! holding under `preload_elastic`), and the readings get the twin's noise, drawn by the twin
//! ([`DriveStream`]): encoder errors on the holding drives (their carriers sit off the command
//! by it), reading noise on followers, the machine thermometer's noise on `temp_machine`. A fault adds a drift between a drive's
//! encoder and its carrier, ramped linearly over the stream: the drive believes it holds its
//! command while its carrier moves, the way a slipping scale or a loose encoder head does.

use anyhow::{bail, Result};
use rpkm_core::design::{CENTRE, CIRCLE_RADIUS_MM};
use rpkm_msgs::ActuatorState;
use rpkm_twin::{DriveStream, Twin};

use crate::campaign_bag::stamp_from_seconds;
use crate::units::set_drive_positions_mm;

/// Seconds per turn of the circular stream (314 mm/s on the 100 mm circle).
pub const CIRCLE_PERIOD_S: f64 = 2.0;

/// Path of the commanded TCP during a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StreamPath {
    /// The circular test's circle: radius 100 mm around (0, 1700) mm, one turn every 2 s,
    /// starting at (100, 1700) mm.
    Circle,
    /// Standing still at (0, 1700) mm.
    Hold,
}

/// A drive whose carrier drifts away from what its encoder reads.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Fault {
    /// Drive index 0..3 (q1..q4).
    pub drive: usize,
    /// Drift at the end of the stream, mm (linear from 0).
    pub max_mm: f64,
}

impl std::str::FromStr for Fault {
    type Err = String;
    /// `q3=0.8`: drive q3 drifts to +0.8 mm.
    fn from_str(s: &str) -> Result<Self, String> {
        let err = || format!("{s:?}: expected qN=MM with N in 1..4, e.g. q3=0.8");
        let (name, mm) = s.split_once('=').ok_or_else(err)?;
        let drive = match name.trim() {
            "q1" => 0,
            "q2" => 1,
            "q3" => 2,
            "q4" => 3,
            _ => return Err(err()),
        };
        let max_mm: f64 = mm.trim().parse().map_err(|_| err())?;
        if !max_mm.is_finite() {
            return Err(err());
        }
        Ok(Self { drive, max_mm })
    }
}

/// What to stream.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct StreamSpec {
    /// Samples per second.
    pub hz: f64,
    /// Length, s.
    pub seconds: f64,
    pub motion: StreamPath,
    pub fault: Option<Fault>,
    /// Twin time of the first sample, s.
    pub start_s: f64,
    /// `seq` of the first sample.
    pub first_seq: u64,
}

impl StreamSpec {
    /// Number of samples: `hz * seconds`, rounded.
    pub fn samples(&self) -> u64 {
        rpkm_core::convert::round_u64(self.hz * self.seconds)
    }

    /// Twin time of sample `k`, s.
    pub fn time(&self, k: u64) -> f64 {
        self.start_s + k as f64 / self.hz
    }

    /// Commanded TCP of sample `k`, mm.
    pub fn target(&self, k: u64) -> (f64, f64) {
        match self.motion {
            StreamPath::Hold => CENTRE,
            StreamPath::Circle => {
                let a = std::f64::consts::TAU * (k as f64 / self.hz) / CIRCLE_PERIOD_S;
                (
                    CENTRE.0 + CIRCLE_RADIUS_MM * a.cos(),
                    CENTRE.1 + CIRCLE_RADIUS_MM * a.sin(),
                )
            }
        }
    }

    /// Drift of the faulty drive at sample `k`, mm: 0 at the first sample, `max_mm` at the last.
    pub fn fault_mm(&self, k: u64) -> f64 {
        match self.fault {
            None => 0.0,
            Some(f) => {
                let n = self.samples();
                if n <= 1 {
                    f.max_mm
                } else {
                    f.max_mm * k as f64 / (n - 1) as f64
                }
            }
        }
    }
}

/// Runs the stream on `twin` and hands every sample to `emit`, in order; the covariates are
/// `[temp_machine]` as in the twin's campaigns. Returns the number of samples.
pub fn run(
    twin: &Twin,
    spec: &StreamSpec,
    mut emit: impl FnMut(u64, &ActuatorState) -> Result<()>,
) -> Result<u64> {
    if !(spec.hz > 0.0 && spec.hz.is_finite()) {
        bail!("stream rate {} Hz: expected a positive number", spec.hz);
    }
    if !(spec.seconds > 0.0 && spec.seconds.is_finite()) {
        bail!(
            "stream length {} s: expected a positive number",
            spec.seconds
        );
    }
    let mut drives = DriveStream::new(twin);
    let n = spec.samples();
    let mut msg = ActuatorState::default();
    for k in 0..n {
        let t = spec.time(k);
        let (x, y) = spec.target(k);
        let mut offset = [0.0; 4];
        if let Some(f) = spec.fault {
            offset[f.drive] = spec.fault_mm(k);
        }
        let s = drives.sample(x, y, t, offset)?;
        let Some(stamp) = stamp_from_seconds(t) else {
            bail!("stream time {t} s does not fit a ROS time stamp");
        };
        msg.stamp = stamp;
        msg.seq = spec.first_seq + k;
        set_drive_positions_mm(&mut msg, s.q);
        msg.force = s.force;
        msg.follower = s.follower;
        // One covariate always fits the eight slots.
        let _ = msg.set_covariates(&[s.temp_c]);
        emit(k, &msg)?;
    }
    Ok(n)
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;

    #[test]
    fn fault_parses_and_ramps() {
        let f: Fault = "q3=0.8".parse().expect("valid");
        assert_eq!(
            f,
            Fault {
                drive: 2,
                max_mm: 0.8
            }
        );
        assert!("q5=1".parse::<Fault>().is_err());
        assert!("q3".parse::<Fault>().is_err());
        let spec = StreamSpec {
            hz: 1000.0,
            seconds: 2.0,
            motion: StreamPath::Hold,
            fault: Some(f),
            start_s: 1.0,
            first_seq: 0,
        };
        assert_eq!(spec.samples(), 2000);
        assert_eq!(spec.fault_mm(0), 0.0);
        assert_eq!(spec.fault_mm(1999), 0.8);
        assert_eq!(spec.time(1000), 2.0);
    }
}
