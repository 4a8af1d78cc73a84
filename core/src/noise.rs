//! Measurement noise of the instruments and encoders: a value, not a constant. The spec's
//! figures ("Workspace and measurement campaigns") are only the [`NoiseModel::default`]; a user
//! states their own (`--noise lt=0.005,encoder=0.0005`), and the calibration estimates each
//! group's level from the campaign itself ([`crate::variance`]).
//!
//! Every calibration row knows how much of its variance comes from each noise [`Group`]
//! ([`Parts`]), so that the groups' levels can be estimated from the residuals
//! (variance-component estimation) and the rows re-weighted with the estimates.

use crate::campaign::Instrument;
use nalgebra::{Matrix2, Matrix4, Vector2};

/// A source of noise whose level is stated and estimated on its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
pub enum Group {
    /// Laser tracker, along the beam (its interferometer / ADM).
    Lt,
    /// Laser tracker, across the beam (its angle encoders: grows with distance).
    LtAcross,
    /// Grid encoder (KGM), per coordinate.
    Kgm,
    /// Double ball-bar distance.
    Dbb,
    /// Laser interferometer, one coordinate.
    Li,
    /// Platform angle optics.
    Psi,
    /// Actuator encoders (the follower encoders of self-calibration included).
    Encoder,
    /// Drive forces, from the motor currents (N).
    Force,
    /// The drives' position noise as their forces see it, all four holding their commands
    /// ([`DriveNoise`]): the same encoders, a level of its own (see
    /// [`NoiseModel::drive_position_mm`]).
    DrivePosition,
}

/// Number of noise groups.
pub const N_GROUPS: usize = 9;

/// Variance (mm² or rad²) a row receives from each group, in [`Group::ALL`] order.
pub type Parts = [f64; N_GROUPS];

impl Group {
    /// Every group, in the order of [`Parts`].
    pub const ALL: [Group; N_GROUPS] = [
        Group::Lt,
        Group::LtAcross,
        Group::Kgm,
        Group::Dbb,
        Group::Li,
        Group::Psi,
        Group::Encoder,
        Group::Force,
        Group::DrivePosition,
    ];

    /// Index in [`Parts`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// Name in reports and in `--noise` (`lt`, `lt_across`, `kgm`, `dbb`, `li`, `psi`,
    /// `encoder`, `force`, `drive_position`).
    pub fn name(self) -> &'static str {
        match self {
            Group::Lt => "lt",
            Group::LtAcross => "lt_across",
            Group::Kgm => "kgm",
            Group::Dbb => "dbb",
            Group::Li => "li",
            Group::Psi => "psi",
            Group::Encoder => "encoder",
            Group::Force => "force",
            Group::DrivePosition => "drive_position",
        }
    }

    /// How a σ of the group is reported: the factor from its unit (mm, rad, N) and the
    /// reported unit.
    pub fn report_unit(self) -> (f64, &'static str) {
        match self {
            Group::Psi => (1e6, "urad"),
            Group::Force => (1.0, "N"),
            _ => (1e3, "um"),
        }
    }

    /// Whether the group's σ is an angle (rad) rather than a length (mm).
    pub fn is_angle(self) -> bool {
        self == Group::Psi
    }

    /// The group of a scalar reading of `instrument` (None: it measures nothing itself).
    pub fn of_scalar(instrument: Instrument) -> Option<Group> {
        match instrument {
            Instrument::Dbb | Instrument::Circle => Some(Group::Dbb),
            Instrument::LiX | Instrument::LiY => Some(Group::Li),
            Instrument::LiPsi => Some(Group::Psi),
            Instrument::SelfCal => Some(Group::Encoder),
            Instrument::Kgm => Some(Group::Kgm),
            Instrument::Lt => Some(Group::Lt),
            Instrument::None => None,
        }
    }
}

/// The instruments that read the TCP's (x, y), each with its own noise shape: the tracker
/// (along and across its beam) and the grid encoder (isotropic). A new 2-D instrument is a
/// new variant, so that every noise formula must say what it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum XyInstrument {
    Lt,
    Kgm,
}

impl XyInstrument {
    /// The 2-D instrument `instrument` is, if it is one.
    pub fn of(instrument: Instrument) -> Option<XyInstrument> {
        match instrument {
            Instrument::Lt => Some(XyInstrument::Lt),
            Instrument::Kgm => Some(XyInstrument::Kgm),
            Instrument::Dbb
            | Instrument::LiX
            | Instrument::LiY
            | Instrument::LiPsi
            | Instrument::SelfCal
            | Instrument::Circle
            | Instrument::None => None,
        }
    }
}

/// Noise of every instrument and of the actuator encoders: standard deviations in mm (rad for
/// ψ), per coordinate.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct NoiseModel {
    /// Position of the laser tracker in the machine frame, mm (the beam direction at a pose).
    pub tracker_position: [f64; 2],
    /// Laser tracker along the beam.
    pub lt_along_mm: f64,
    /// Laser tracker across the beam: `lt_across_mm` + `lt_across_per_m_mm` per metre of
    /// distance.
    pub lt_across_mm: f64,
    pub lt_across_per_m_mm: f64,
    pub kgm_mm: f64,
    pub dbb_mm: f64,
    pub li_mm: f64,
    pub psi_rad: f64,
    /// Actuator encoders (linear scales of the direct drives).
    pub encoder_mm: f64,
    /// Drive forces read from the motor currents, N.
    pub force_n: f64,
    /// The drives' position noise in their force rows (mm): the encoders' noise, which the
    /// forces see through the rods' stiffness while all four drives hold their commands
    /// ([`DriveNoise`]). Its own group, not `encoder_mm`'s: the encoder group's level is
    /// also set by the loaded tracker poses' incompatibility rows, where a model without
    /// the rods' stretch leaves 0.1 mm of misfit (a twin's campaign calibrated without
    /// `preload_elastic`: 20 µm, the estimation's cap), and force rows weighed by that lose
    /// their information.
    pub drive_position_mm: f64,
}

impl Default for NoiseModel {
    /// The spec's figures: tracker in front of the machine on its axis (TCP distances
    /// 2.2-4.2 m), 5 µm along the beam, 18 µm + 3 µm/m across; grid encoder, ball-bar and
    /// interferometer about 1 µm; angle optics 1 µrad. The spec gives no encoder noise; a
    /// linear scale of this class reads to a few tenths of a micrometre.
    fn default() -> Self {
        NoiseModel {
            tracker_position: [0.0, -1500.0],
            lt_along_mm: 0.005,
            lt_across_mm: 0.018,
            lt_across_per_m_mm: 0.003,
            kgm_mm: 0.001,
            dbb_mm: 0.001,
            li_mm: 0.001,
            psi_rad: 1e-6,
            encoder_mm: 0.0002,
            // the spec gives none: a drive's force from its current, a few N of a 2 kN drive
            force_n: 5.0,
            // the same encoders
            drive_position_mm: 0.0002,
        }
    }
}

/// A `--noise` statement that cannot be read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NoiseSpecError {
    #[error("`{0}`: expected NAME=VALUE (e.g. lt=0.005)")]
    Syntax(String),
    #[error("unknown noise name `{name}`, expected one of {known}")]
    UnknownName { name: String, known: &'static str },
    #[error("`{name}={value}`: expected a positive finite number (mm, rad for psi)")]
    Value { name: String, value: String },
}

const NAMES: &str = "lt (isotropic tracker), lt_along, lt_across, lt_across_per_m, kgm, dbb, li, \
                     psi, encoder, force (N), drive_position, tracker_x, tracker_y";

impl NoiseModel {
    /// The default with the statements `name=value,...` applied (mm, rad for `psi`):
    /// `lt` sets an isotropic tracker (along = across, no growth with distance).
    pub fn parse(spec: &str) -> Result<NoiseModel, NoiseSpecError> {
        let mut m = NoiseModel::default();
        for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, value) = item
                .split_once('=')
                .ok_or_else(|| NoiseSpecError::Syntax(item.to_owned()))?;
            let (name, value) = (name.trim(), value.trim());
            let bad = || NoiseSpecError::Value {
                name: name.to_owned(),
                value: value.to_owned(),
            };
            let v: f64 = value.parse().map_err(|_| bad())?;
            // a position may be anywhere, a growth may be zero, a noise level must be positive
            let ok = match name {
                "tracker_x" | "tracker_y" => v.is_finite(),
                "lt_across_per_m" => v.is_finite() && v >= 0.0,
                _ => v.is_finite() && v > 0.0,
            };
            if !ok {
                return Err(bad());
            }
            m.set(name, v)?;
        }
        Ok(m)
    }

    /// The model with the σ an instrument states for its own readings (mm, rad for ψ): the
    /// tracker's along-beam σ (what `TcpMeasurement::sigma` carries for it), the grid
    /// encoder's, the ball bar's, the interferometer's, the encoders' for a self-calibration
    /// reading. `Instrument::None` reads nothing and changes nothing.
    pub fn with_instrument_sigma(
        mut self,
        instrument: Instrument,
        sigma: f64,
    ) -> Result<NoiseModel, NoiseSpecError> {
        let name = match instrument {
            Instrument::Lt => "lt_along",
            Instrument::Kgm => "kgm",
            Instrument::Dbb | Instrument::Circle => "dbb",
            Instrument::LiX | Instrument::LiY => "li",
            Instrument::LiPsi => "psi",
            Instrument::SelfCal => "encoder",
            Instrument::None => return Ok(self),
        };
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(NoiseSpecError::Value {
                name: name.to_owned(),
                value: sigma.to_string(),
            });
        }
        self.set(name, sigma)?;
        Ok(self)
    }

    fn set(&mut self, name: &str, v: f64) -> Result<(), NoiseSpecError> {
        match name {
            "lt" => {
                self.lt_along_mm = v;
                self.lt_across_mm = v;
                self.lt_across_per_m_mm = 0.0;
            }
            "lt_along" => self.lt_along_mm = v,
            "lt_across" => self.lt_across_mm = v,
            "lt_across_per_m" => self.lt_across_per_m_mm = v,
            "kgm" => self.kgm_mm = v,
            "dbb" => self.dbb_mm = v,
            "li" => self.li_mm = v,
            "psi" => self.psi_rad = v,
            "encoder" => self.encoder_mm = v,
            "force" => self.force_n = v,
            "drive_position" => self.drive_position_mm = v,
            "tracker_x" => self.tracker_position[0] = v,
            "tracker_y" => self.tracker_position[1] = v,
            _ => {
                return Err(NoiseSpecError::UnknownName {
                    name: name.to_owned(),
                    known: NAMES,
                })
            }
        }
        Ok(())
    }

    /// The model with every group's σ multiplied by `factor[group]`.
    #[must_use]
    pub fn scaled(&self, factor: &[f64; N_GROUPS]) -> NoiseModel {
        let f = |g: Group| factor[g.index()];
        NoiseModel {
            tracker_position: self.tracker_position,
            lt_along_mm: self.lt_along_mm * f(Group::Lt),
            lt_across_mm: self.lt_across_mm * f(Group::LtAcross),
            lt_across_per_m_mm: self.lt_across_per_m_mm * f(Group::LtAcross),
            kgm_mm: self.kgm_mm * f(Group::Kgm),
            dbb_mm: self.dbb_mm * f(Group::Dbb),
            li_mm: self.li_mm * f(Group::Li),
            psi_rad: self.psi_rad * f(Group::Psi),
            encoder_mm: self.encoder_mm * f(Group::Encoder),
            force_n: self.force_n * f(Group::Force),
            drive_position_mm: self.drive_position_mm * f(Group::DrivePosition),
        }
    }

    /// σ of `group` (the tracker's across-beam σ at `tracker_distance_mm`).
    pub fn sigma(&self, group: Group, tracker_distance_mm: f64) -> f64 {
        match group {
            Group::Lt => self.lt_along_mm,
            Group::LtAcross => self.lt_across(tracker_distance_mm),
            Group::Kgm => self.kgm_mm,
            Group::Dbb => self.dbb_mm,
            Group::Li => self.li_mm,
            Group::Psi => self.psi_rad,
            Group::Encoder => self.encoder_mm,
            Group::Force => self.force_n,
            Group::DrivePosition => self.drive_position_mm,
        }
    }

    fn lt_across(&self, distance_mm: f64) -> f64 {
        self.lt_across_mm + crate::units::m_from_mm(self.lt_across_per_m_mm * distance_mm)
    }

    /// Distance (mm) from the tracker to `tcp`.
    pub fn tracker_distance(&self, tcp: Vector2<f64>) -> f64 {
        (tcp - Vector2::from(self.tracker_position)).norm()
    }

    /// Beam and cross-beam unit vectors at `tcp`, and the two variances (mm²).
    fn lt_frame(&self, tcp: Vector2<f64>) -> (Vector2<f64>, Vector2<f64>, f64, f64) {
        let beam = tcp - Vector2::from(self.tracker_position);
        let dist = beam.norm();
        // on the tracker itself the beam has no direction: any frame will do
        let u = if dist > 0.0 {
            beam / dist
        } else {
            Vector2::new(0.0, 1.0)
        };
        let v = Vector2::new(-u.y, u.x);
        (u, v, self.lt_along_mm.powi(2), self.lt_across(dist).powi(2))
    }

    /// The tracker's beam and cross-beam unit vectors at `tcp`.
    pub fn beam_frame(&self, tcp: Vector2<f64>) -> (Vector2<f64>, Vector2<f64>) {
        let (u, v, _, _) = self.lt_frame(tcp);
        (u, v)
    }

    /// Covariance (mm²) of an (x, y) reading of a TCP-measuring instrument at `tcp`.
    pub fn xy_covariance(&self, instrument: XyInstrument, tcp: Vector2<f64>) -> Matrix2<f64> {
        match instrument {
            XyInstrument::Lt => {
                let (u, v, along, across) = self.lt_frame(tcp);
                u * u.transpose() * along + v * v.transpose() * across
            }
            XyInstrument::Kgm => Matrix2::identity() * self.kgm_mm.powi(2),
        }
    }

    /// Variance parts of `g · (x, y)` of a reading of a 2-D instrument at `tcp`.
    pub fn xy_parts(&self, instrument: XyInstrument, tcp: Vector2<f64>, g: Vector2<f64>) -> Parts {
        let mut parts = [0.0; N_GROUPS];
        match instrument {
            XyInstrument::Lt => {
                let (u, v, along, across) = self.lt_frame(tcp);
                parts[Group::Lt.index()] = g.dot(&u).powi(2) * along;
                parts[Group::LtAcross.index()] = g.dot(&v).powi(2) * across;
            }
            XyInstrument::Kgm => {
                parts[Group::Kgm.index()] = g.norm_squared() * self.kgm_mm.powi(2);
            }
        }
        parts
    }

    /// Standard deviation of a scalar reading: r of the ball-bar (mm), one LI coordinate (mm),
    /// ψ (rad), a follower encoder (mm); a 2-D instrument's per-coordinate σ (the tracker's
    /// along the beam). None for `none`, which measures nothing.
    pub fn scalar_sigma(&self, instrument: Instrument) -> Option<f64> {
        Group::of_scalar(instrument).map(|g| self.sigma(g, 0.0))
    }

    /// Variance parts of `gain` times one scalar reading of `instrument`.
    pub fn scalar_parts(&self, instrument: Instrument, gain: f64) -> Parts {
        let mut parts = [0.0; N_GROUPS];
        if let Some(g) = Group::of_scalar(instrument) {
            parts[g.index()] = (gain * self.sigma(g, 0.0)).powi(2);
        }
        parts
    }

    /// The drive forces' noise: the currents' and the drives' positions' levels
    /// ([`DriveNoise`]).
    pub fn drives(&self) -> DriveNoise {
        DriveNoise {
            force_n: self.force_n,
            encoder_mm: self.drive_position_mm,
        }
    }

    /// Variance parts of one drive force reading (N²).
    pub fn force_parts(&self) -> Parts {
        let mut parts = [0.0; N_GROUPS];
        parts[Group::Force.index()] = self.force_n.powi(2);
        parts
    }

    /// Variance parts of encoder noise entering with total squared gain `gain2`.
    pub fn encoder_parts(&self, gain2: f64) -> Parts {
        let mut parts = [0.0; N_GROUPS];
        parts[Group::Encoder.index()] = gain2 * self.encoder_mm.powi(2);
        parts
    }
}

/// The noise of the four drive forces of one pose with all four drives position-controlled,
/// as a row of a calibration or a sample of the online tracker compares them: the model's
/// forces at the recorded carrier positions minus the recorded forces, r = K e − n (K the
/// 4 × 4 derivative of the forces by the carrier positions, e the encoders' errors, n the
/// currents' noise). The drives hold their commands, so an encoder's error is a real
/// incompatibility of the loop: 0.2 µm of it is 10-20 N of force by the rods' stiffness
/// (97.7 kN/mm), several times the currents' few N. The forces' covariance is
/// σ_f² I + σ_e² K Kᵀ; in the eigenvectors of K Kᵀ ([`ForceModes`]) both noises are diagonal
/// (the currents' is isotropic), so the four combinations are independent at any levels.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct DriveNoise {
    /// σ of a drive force read from the motor current, N.
    pub force_n: f64,
    /// σ of a drive's encoder, mm.
    pub encoder_mm: f64,
}

/// The four force combinations of one pose that are independent under [`DriveNoise`]: the
/// eigenvectors of K Kᵀ, largest eigenvalue first. K has rank two (the forces of a preload
/// span two modes; on the twin the third's share is a thousandth of the second's, the
/// central differences' round-off), so the first two carry the encoders' noise and the
/// geometry's signal, the last two the currents' noise alone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceModes {
    /// Column m: the m-th combination's weights on f1..f4 (unit length).
    pub basis: Matrix4<f64>,
    /// Per combination: its variance (N²) split by group, the currents' σ_f² and the
    /// drives' positions' σ_e² λ_m ([`Group::DrivePosition`]).
    pub parts: [Parts; 4],
}

impl DriveNoise {
    /// The independent combinations of the four forces of a pose whose forces move by
    /// `gains` (N/mm, row a: force a, column b: carrier b) with the carrier positions.
    pub fn modes(&self, gains: &Matrix4<f64>) -> ForceModes {
        let eig = (gains * gains.transpose()).symmetric_eigen();
        let mut order = [0, 1, 2, 3];
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let mut parts = [[0.0; N_GROUPS]; 4];
        let mut basis = Matrix4::zeros();
        for (m, &j) in order.iter().enumerate() {
            basis.set_column(m, &eig.eigenvectors.column(j));
            // round-off leaves the rank-two K's null eigenvalues a hair below zero
            let share = eig.eigenvalues[j].max(0.0) * self.encoder_mm.powi(2);
            parts[m][Group::Force.index()] = self.force_n.powi(2);
            parts[m][Group::DrivePosition.index()] = share;
        }
        ForceModes { basis, parts }
    }
}

impl ForceModes {
    /// Variance of combination `m`, N².
    pub fn variance(&self, m: usize) -> f64 {
        self.parts[m].iter().sum()
    }

    /// The forces' covariance σ_f² I + σ_e² K Kᵀ (N²).
    pub fn covariance(&self) -> Matrix4<f64> {
        self.weighted(|v| v)
    }

    /// Its inverse, the forces' information (N⁻²), from the combinations: exact where the
    /// encoders' share dwarfs the currents'.
    pub fn information(&self) -> Matrix4<f64> {
        self.weighted(|v| 1.0 / v)
    }

    /// Σ_m f(variance m) b_m b_mᵀ.
    fn weighted(&self, f: impl Fn(f64) -> f64) -> Matrix4<f64> {
        let mut out = Matrix4::zeros();
        for m in 0..4 {
            let b = self.basis.column(m);
            out += b * b.transpose() * f(self.variance(m));
        }
        out
    }
}

/// Sum of two variance decompositions.
pub fn add(a: Parts, b: Parts) -> Parts {
    std::array::from_fn(|k| a[k] + b[k])
}

/// σ of a row from its variance parts.
pub fn sigma_of(parts: &Parts) -> f64 {
    parts.iter().sum::<f64>().sqrt()
}

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;

    #[test]
    fn parse_sets_an_isotropic_tracker_and_keeps_the_rest() {
        let m = NoiseModel::parse("lt=0.004, encoder=0.0005").expect("valid");
        let d = NoiseModel::default();
        assert_eq!(m.lt_along_mm, 0.004);
        assert_eq!(m.lt_across_mm, 0.004);
        assert_eq!(m.lt_across_per_m_mm, 0.0);
        assert_eq!(m.encoder_mm, 0.0005);
        assert_eq!(m.kgm_mm, d.kgm_mm);
        let c = m.xy_covariance(XyInstrument::Lt, Vector2::new(300.0, 2000.0));
        assert!((c[(0, 0)] - 1.6e-5).abs() < 1e-12 && c[(0, 1)].abs() < 1e-12);
    }

    #[test]
    fn parse_names_what_is_wrong() {
        assert!(matches!(
            NoiseModel::parse("laser=1"),
            Err(NoiseSpecError::UnknownName { .. })
        ));
        assert!(matches!(
            NoiseModel::parse("kgm=-1"),
            Err(NoiseSpecError::Value { .. })
        ));
        assert!(matches!(
            NoiseModel::parse("kgm=nan"),
            Err(NoiseSpecError::Value { .. })
        ));
        assert!(matches!(
            NoiseModel::parse("kgm"),
            Err(NoiseSpecError::Syntax(_))
        ));
    }

    #[test]
    fn parts_of_a_tracker_reading_add_up_to_its_covariance() {
        let m = NoiseModel::default();
        let tcp = Vector2::new(120.0, 1800.0);
        let g = Vector2::new(0.3, -1.2);
        let parts = m.xy_parts(XyInstrument::Lt, tcp, g);
        let var = (g.transpose() * m.xy_covariance(XyInstrument::Lt, tcp) * g)[0];
        assert!((parts.iter().sum::<f64>() - var).abs() < 1e-15);
        // on the tracker's own position the frame is still defined
        let on = m.xy_parts(XyInstrument::Lt, Vector2::from(m.tracker_position), g);
        assert!(on.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn force_modes_are_the_forces_covariance_diagonalised() {
        let k = Matrix4::new(
            -97.7, 60.0, -12.0, 3.0, 40.0, -97.7, 8.0, -1.0, -20.0, 15.0, -97.7, 30.0, 5.0, -2.0,
            44.0, -97.7,
        ) * 1e3;
        let noise = DriveNoise {
            force_n: 3.0,
            encoder_mm: 2e-4,
        };
        let modes = noise.modes(&k);
        let want = Matrix4::identity() * 9.0 + k * k.transpose() * 4e-8;
        assert!((modes.covariance() - want).norm() < 1e-9 * want.norm());
        assert!((modes.information() * want - Matrix4::identity()).norm() < 1e-9);
        // largest encoder share first, the currents' share alike in every combination
        let enc = |m: usize| modes.parts[m][Group::DrivePosition.index()];
        assert!(enc(0) >= enc(1) && enc(1) >= enc(2) && enc(2) >= enc(3));
        assert!((0..4).all(|m| (modes.parts[m][Group::Force.index()] - 9.0).abs() < 1e-12));
    }

    #[test]
    fn scaling_multiplies_each_group() {
        let mut f = [1.0; N_GROUPS];
        f[Group::Encoder.index()] = 2.5;
        f[Group::LtAcross.index()] = 0.5;
        let m = NoiseModel::default().scaled(&f);
        assert!((m.encoder_mm - 0.0005).abs() < 1e-15);
        assert!((m.lt_across_mm - 0.009).abs() < 1e-15);
        assert_eq!(m.lt_along_mm, 0.005);
    }
}
