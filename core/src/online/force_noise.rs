//! The force noise the innovations show, from the differences of successive innovations.

use nalgebra::{Matrix4, Vector4};

/// The covariance of the force noise as the innovations show it (N²): the filter's stated
/// noise (`force_sigma_n` and `encoder_sigma_mm` through the loop's stiffness,
/// [`DriveNoise`]) is a statement, not the machine's levels (on the twin 3 N of currents
/// where 5 N is stated; an encoder's few tenths of a µm are several N on the four drives'
/// preload at once, one direction of the four forces: 7 N rms a drive at the truth). The change
/// since the reference is K v summed through the filter's gains, so its covariance is
/// K R Kᵀ with the noise v really has, whatever the filter assumed when it chose K (the
/// Joseph form of a suboptimal gain).
///
/// Estimated from the differences of successive innovations, ½ mean Δy Δyᵀ: the noise is
/// independent from sample to sample, so a difference carries it twice, while the
/// innovation's slow part (the filter's lag behind a drift, its prediction error) cancels.
/// The innovations themselves (mean y yᵀ) take that lag for noise: under a creep of l3 they
/// widened M until the drift test lost it for a minute at a time. Their normalised mean
/// (χ² per dof) says nothing of R here: it is 0.18 on the twin, the random walk's H P Hᵀ
/// (10⁴ N² a sample at 0.15 mm/√h) dwarfing R in every direction the forces see.
#[derive(Clone, Copy, Debug)]
pub(super) struct ForceNoise {
    /// ½ Σ Δy Δyᵀ, the stated R as [`STATED_NOISE_SAMPLES`] samples included.
    pub(super) sum: Matrix4<f64>,
    pub(super) n: f64,
    /// The last applied sample's innovation.
    pub(super) last: Option<Vector4<f64>>,
}

/// The stated force σ counts as this many samples in [`ForceNoise`]'s mean: it holds the
/// first samples (a 4 × 4 covariance from fewer than its 10 entries would be singular) and
/// weighs nothing after the first minute (600 samples at 10 Hz).
const STATED_NOISE_SAMPLES: f64 = 10.0;

impl ForceNoise {
    pub(super) fn stated(r: &Matrix4<f64>) -> ForceNoise {
        ForceNoise {
            sum: r * STATED_NOISE_SAMPLES,
            n: STATED_NOISE_SAMPLES,
            last: None,
        }
    }

    /// Adds the innovation `y` of an applied sample (its difference from the last one).
    pub(super) fn add(&mut self, y: &Vector4<f64>) {
        if let Some(last) = self.last.replace(*y) {
            let d = y - last;
            self.sum += d * d.transpose() * 0.5;
            self.n += 1.0;
        }
    }

    pub(super) fn covariance(&self) -> Matrix4<f64> {
        self.sum / self.n
    }
}
