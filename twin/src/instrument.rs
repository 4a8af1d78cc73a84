//! The twin's relative instruments: the reading each setup is zeroed on, the move from
//! there, the instrument's noise and its drift since the zero.

use super::machine::{gauss, MachineState, ResetReading, Twin, TwinError, ZeroDrift};
use nalgebra::{Cholesky, Matrix2, Rotation2, Vector2};
use rpkm_core::campaign::{Instrument, MeasuredPose};
use rpkm_core::design::PlannedPose;
use rpkm_core::noise::{NoiseModel, XyInstrument};

/// How far a pose moved from its setup's reset pose: TCP displacement in the instrument's
/// frame, platform rotation, and the TCP (where the tracker's beam points).
struct Moved {
    d: Vector2<f64>,
    dpsi: f64,
    tcp: Vector2<f64>,
    /// The error of the reading the instrument was zeroed on (x, y; a single coordinate or
    /// ψ in x), which every reading of the setup carries, less the instrument's drift since
    /// ([`ZeroDrift`]): what the reading is short of the move.
    zero: Vector2<f64>,
}

/// A relative setup's zero: where the machine stood at its reset pose, the error of the
/// reading it was zeroed on, and when.
pub(super) struct Zeroed {
    setup: String,
    tcp: Vector2<f64>,
    psi: f64,
    error: Vector2<f64>,
    t: f64,
}

/// A square root L (L Lᵀ = cov) of a reading's 2 × 2 covariance: its Cholesky factor, or,
/// when one direction has no noise at all (a singular covariance, e.g. a tracker rated 0
/// across the beam), the symmetric square root from its eigen-decomposition, so that the
/// other direction's noise is still drawn.
fn xy_factor(cov: Matrix2<f64>) -> Matrix2<f64> {
    if let Some(c) = Cholesky::new(cov) {
        return c.l();
    }
    let eig = cov.symmetric_eigen();
    let root = eig.eigenvalues.map(|v| v.max(0.0).sqrt());
    eig.eigenvectors * Matrix2::from_diagonal(&root) * eig.eigenvectors.transpose()
}

/// A drift the twin can apply: a relative instrument's, finite.
pub(super) fn check_drift(d: &ZeroDrift) -> Result<(), TwinError> {
    let bad = |why| {
        Err(TwinError::BadDrift {
            instrument: d.instrument,
            why,
        })
    };
    if !d.instrument.is_relative() {
        return bad("only a relative instrument (lt, kgm, dbb, li_x, li_y, li_psi) has a zero");
    }
    if !d.rate_per_s.iter().all(|v| v.is_finite()) {
        return bad("the rate is not a finite number");
    }
    Ok(())
}

impl Twin {
    /// The reading of a relative instrument (or a ball-bar circle's) at a pose in state `st`
    /// at time `t`: its setup's zero taken at its reset pose (kept in `zeroed`), then the
    /// move from there, with noise `noise` scaled by `k`.
    pub(super) fn read_relative(
        &mut self,
        plan: &PlannedPose,
        (st, t): (&MachineState, f64),
        (noise, k): (&NoiseModel, f64),
        zeroed: &mut Option<Zeroed>,
        pose: &mut MeasuredPose,
    ) -> Result<(), TwinError> {
        if plan.reset {
            *zeroed = Some(Zeroed {
                setup: plan.setup.clone(),
                tcp: st.tcp,
                psi: st.psi,
                error: self.zero_error(plan.instrument, st.tcp, noise, k),
                t,
            });
        }
        if !plan.instrument.takes_reset() {
            return Ok(());
        }
        let Some(z) = zeroed.as_ref().filter(|z| z.setup == plan.setup) else {
            return Err(TwinError::NoReset {
                setup: plan.setup.clone(),
            });
        };
        let drift = self
            .config
            .drift
            .filter(|d| d.instrument == plan.instrument)
            .map_or([0.0; 2], |d| d.after(t - z.t));
        let theta = self.alignment_angle(&plan.setup);
        let moved = Moved {
            d: Rotation2::new(theta) * (st.tcp - z.tcp),
            dpsi: st.psi - z.psi,
            tcp: st.tcp,
            zero: z.error - Vector2::from(drift),
        };
        self.read_instrument(plan, &moved, noise, k, pose);
        Ok(())
    }

    /// The reading of a relative instrument at a pose that moved by `moved` from its setup's
    /// reset, with noise `noise` scaled by `k` (0: noiseless, the draws still made).
    fn read_instrument(
        &mut self,
        plan: &PlannedPose,
        moved: &Moved,
        noise: &NoiseModel,
        k: f64,
        pose: &mut MeasuredPose,
    ) {
        let (d, dpsi) = (moved.d, moved.dpsi);
        let m = plan.instrument.measures();
        if plan.reset {
            pose.x = m.x.then_some(0.0);
            pose.y = m.y.then_some(0.0);
            pose.r = m.r.then_some(0.0);
            pose.psi = m.psi.then_some(0.0);
            return;
        }
        match plan.instrument {
            Instrument::Lt | Instrument::Kgm => {
                let xy = if plan.instrument == Instrument::Lt {
                    XyInstrument::Lt
                } else {
                    XyInstrument::Kgm
                };
                let cov = noise.xy_covariance(xy, moved.tcp);
                let e = xy_factor(cov) * Vector2::new(gauss(&mut self.rng), gauss(&mut self.rng));
                pose.x = Some(d.x + k * e.x - moved.zero.x);
                pose.y = Some(d.y + k * e.y - moved.zero.y);
            }
            Instrument::LiX
            | Instrument::LiY
            | Instrument::Dbb
            | Instrument::Circle
            | Instrument::LiPsi => {
                let sigma = noise.scalar_sigma(plan.instrument).unwrap_or(0.0);
                // a ball-bar's zero is where the machine stood: `zero` is 0 for it
                let e = k * sigma * gauss(&mut self.rng) - moved.zero.x;
                match plan.instrument {
                    Instrument::LiX => pose.x = Some(d.x + e),
                    Instrument::LiY => pose.y = Some(d.y + e),
                    Instrument::LiPsi => pose.psi = Some(dpsi + e),
                    _ => pose.r = Some(d.norm() + e),
                }
            }
            Instrument::SelfCal | Instrument::None => {}
        }
    }

    /// The error of the reading a relative instrument is zeroed on at its reset pose (true
    /// TCP `tcp`), with the instrument's noise scaled by `k` ([`ResetReading::Exact`], and
    /// an instrument zeroed on no reading, the ball-bar: zero). Drawn from its own stream.
    fn zero_error(
        &mut self,
        instrument: Instrument,
        tcp: Vector2<f64>,
        noise: &NoiseModel,
        k: f64,
    ) -> Vector2<f64> {
        if self.config.reset == ResetReading::Exact {
            return Vector2::zeros();
        }
        if let Some(xy) = XyInstrument::of(instrument) {
            let e = Vector2::new(gauss(&mut self.reset_rng), gauss(&mut self.reset_rng));
            return k * (xy_factor(noise.xy_covariance(xy, tcp)) * e);
        }
        match instrument {
            Instrument::LiX | Instrument::LiY | Instrument::LiPsi => {
                let sigma = noise.scalar_sigma(instrument).unwrap_or(0.0);
                Vector2::new(k * sigma * gauss(&mut self.reset_rng), 0.0)
            }
            _ => Vector2::zeros(),
        }
    }
}
