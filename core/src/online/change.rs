//! The estimate's change since a reference and its covariance had nothing moved, with the
//! filter's response to a creep.

use super::options::{Covariance, N_STATE};
use crate::params::{Params, N_PARAMS};
use nalgebra::{SMatrix, SVector};

/// What the estimate's change since a reference would be were nothing to have moved: the
/// estimation error evolves as e ← A e + K v (A = I − K H) under noise v alone, so the change
/// e_t − e_r = (Φ − I) e_r + Σ Φ K v, Φ the product of the A since the reference. Its
/// covariance (Φ − I) P_r (Φ − I)ᵀ + M, M ← A M Aᵀ + K R Kᵀ with R the force noise the
/// innovations show ([`ForceNoise`], not the stated σ), stays bounded where the random
/// walk's own covariance grows with time: the random walk lets the estimate follow a drift,
/// and the test still measures the drift against what noise alone would have moved it (the
/// filter's own innovations would not: they are tested against the random walk, which
/// allows any drift this slow). Scaled units, as the filter.
///
/// Beside it, what the filter makes of a parameter that creeps along the input s (the
/// temperature's change since the reference, or the hours where there is no temperature):
/// the truth x_r + e_i s moves the estimate by R e_i, R ← A R + K H s. The forces see a
/// parameter's change only through the combinations they determine, so a creep is compared
/// with the estimate's change through the filter's own response, not as the unit vector.
#[derive(Clone, Debug)]
pub(super) struct ChangeTrack {
    pub(super) p: Params,
    pub(super) cov: Covariance,
    phi: Covariance,
    noise: Covariance,
    pub(super) response: SMatrix<f64, N_STATE, N_PARAMS>,
    pub(super) input: DriftInput,
    /// The input now (K or h since the reference).
    pub(super) s: f64,
    pub(super) t: Option<f64>,
}

/// What a creep is assumed to follow.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DriftInput {
    /// Not yet known (no sample since the reference).
    Unknown,
    /// The temperature (°C at the reference): changes per K.
    Temperature(f64),
    /// Time, where no temperature is given: changes per hour.
    Time,
}

impl ChangeTrack {
    pub(super) fn at(p: Params, cov: &Covariance, t: Option<f64>) -> ChangeTrack {
        ChangeTrack {
            p,
            cov: *cov,
            phi: Covariance::identity(),
            noise: Covariance::zeros(),
            response: SMatrix::zeros(),
            input: DriftInput::Unknown,
            s: 0.0,
            t,
        }
    }

    /// The input at time `t` with temperature `temp_c` (NaN: none), fixing its kind at the
    /// first sample after the reference.
    pub(super) fn input(&mut self, t: f64, temp_c: f64) -> f64 {
        let t0 = *self.t.get_or_insert(t);
        if self.input == DriftInput::Unknown {
            self.input = if temp_c.is_finite() {
                DriftInput::Temperature(temp_c)
            } else {
                DriftInput::Time
            };
        }
        self.s = match self.input {
            DriftInput::Temperature(t_ref) if temp_c.is_finite() => temp_c - t_ref,
            // a thermometer that stops reading: the last change holds
            DriftInput::Temperature(_) => self.s,
            DriftInput::Time | DriftInput::Unknown => (t - t0) / 3600.0,
        };
        self.s
    }

    /// Through one update: `a` = I − K H, `kh` = K H, `krk` = K R̂ Kᵀ.
    pub(super) fn advance(
        &mut self,
        a: &Covariance,
        kh: &Covariance,
        krk: &Covariance,
        t: f64,
        temp_c: f64,
    ) {
        let s = self.input(t, temp_c);
        self.phi = a * self.phi;
        let noise = a * self.noise * a.transpose() + krk;
        self.noise = (noise + noise.transpose()) * 0.5;
        self.response = a * self.response + kh.fixed_view::<N_STATE, N_PARAMS>(0, 0) * s;
    }

    /// The change's covariance under the linear noise model, (Φ − I) P_r (Φ − I)ᵀ + M, over
    /// the parameters (scaled units).
    pub(super) fn covariance(&self) -> SMatrix<f64, N_PARAMS, N_PARAMS> {
        let phi = self.phi.fixed_view::<N_PARAMS, N_STATE>(0, 0)
            - Covariance::identity().fixed_view::<N_PARAMS, N_STATE>(0, 0);
        let cov =
            phi * self.cov * phi.transpose() + self.noise.fixed_view::<N_PARAMS, N_PARAMS>(0, 0);
        (cov + cov.transpose()) * 0.5
    }
}

/// The parameters' change since the reference and its covariance had nothing moved (mm, rad).
#[derive(Clone, Debug, PartialEq)]
pub struct EstimateChange {
    /// Time of the reference, s (None before the first sample).
    pub since_s: Option<f64>,
    /// Estimate now minus the estimate at the reference.
    pub dp: SVector<f64, N_PARAMS>,
    /// Its covariance under noise alone (see [`OnlineEstimator::change`]).
    pub cov: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// Column i: the estimate's change had parameter i crept by one unit (mm, rad) per unit
    /// of the input since the reference.
    pub response: SMatrix<f64, N_PARAMS, N_PARAMS>,
    /// What the creep follows, and its value now (K or h since the reference).
    pub input: DriftInput,
    pub input_now: f64,
}
