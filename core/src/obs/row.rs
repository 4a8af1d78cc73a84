//! What a row measures and holds: its direction, value, derivatives and noise parts, and the
//! model's errors at a pose.

use crate::campaign::{Campaign, Instrument, MeasuredPose};
use crate::elastic::ElasticError;
use crate::geometry::GeometryError;
use crate::noise::Parts;
use crate::params::Row;
use nalgebra::Vector2;

/// What a row measures: the instrument's direction and, for forward rows, the subsystem used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Direction {
    /// Actuator position q1..q4 (index 0..=3) from the inverse model or rgm.
    Q(usize),
    /// Ball-bar distance through the subsystem (q_a, q_b).
    R(usize, usize),
    /// x coordinate through (q_a, q_b).
    X(usize, usize),
    /// y coordinate through (q_a, q_b).
    Y(usize, usize),
    /// platform angle through (q_a, q_b).
    Psi(usize, usize),
    /// q2 from the virtual measurements of the forward step (second step).
    VirtualQ2,
    /// A 2-D instrument's four q rows of one pose, decorrelated ([`decorrelate`]): the TCP
    /// misfit along and across the tracker's beam (x and y for the grid encoder), mm ...
    Along,
    Across,
    /// ... and the two combinations of the four drives the TCP cannot move: the
    /// incompatibility of the recorded drives, which only encoder noise and the geometry set.
    Compat(usize),
    /// Drive force f1..f4 (index 0..=3, N) with all four drives position-controlled: the
    /// model's preload at the recorded positions minus the recorded force.
    F(usize),
    /// The four force rows of a pose decorrelated ([`decorrelate_forces`]): their
    /// combinations along [`ForceModes`], largest encoder share first (N): the preload
    /// modes the drives' position noise enters (two), then those it does not.
    FMode(usize),
}

impl std::fmt::Display for Direction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Direction::Q(i) => write!(f, "q{}", i + 1),
            Direction::R(a, b) => write!(f, "r(q{},q{})", a + 1, b + 1),
            Direction::X(a, b) => write!(f, "x(q{},q{})", a + 1, b + 1),
            Direction::Y(a, b) => write!(f, "y(q{},q{})", a + 1, b + 1),
            Direction::Psi(a, b) => write!(f, "psi(q{},q{})", a + 1, b + 1),
            Direction::VirtualQ2 => write!(f, "q2 (virtual)"),
            Direction::Along => write!(f, "along"),
            Direction::Across => write!(f, "across"),
            Direction::Compat(k) => write!(f, "compat{}", k + 1),
            Direction::F(a) => write!(f, "f{}", a + 1),
            Direction::FMode(k) => write!(f, "fmode{}", k + 1),
        }
    }
}

impl Direction {
    /// Unit of the row's residual: mm, or rad for ψ (or N for a force: see [`Self::is_force`]).
    pub fn is_angle(self) -> bool {
        matches!(self, Direction::Psi(..))
    }

    /// Whether the row's residual is a drive force (N).
    pub fn is_force(self) -> bool {
        matches!(self, Direction::F(..) | Direction::FMode(..))
    }

    /// Whether the row's residual is a length (mm).
    pub fn is_length(self) -> bool {
        !self.is_angle() && !self.is_force()
    }

    /// How a residual of this direction is reported: the factor from its unit (mm, rad, N)
    /// and the reported unit.
    pub fn report_unit(self) -> (f64, &'static str) {
        if self.is_angle() {
            (1e6, "µrad")
        } else if self.is_force() {
            (1.0, "N")
        } else {
            (1e3, "µm")
        }
    }
}

/// One compared value.
#[derive(Clone, Debug)]
pub struct Residual {
    /// Index of the pose in the campaign.
    pub pose: usize,
    pub instrument: Instrument,
    pub direction: Direction,
    /// W_mod − W_meas (mm or rad).
    pub value: f64,
    /// Standard deviation of the row (mm or rad): its weight is 1/sigma.
    pub sigma: f64,
    /// Its variance (sigma²) split by noise group, to estimate each group's level.
    pub parts: Parts,
    /// d value / d p over the 29 parameters.
    pub jacobian: Row,
    /// For virtual rows of the second step: d value / d p_cal, the sensitivity to the
    /// first step's parameters that made the virtual measurement (to propagate their
    /// uncertainty); None for measured rows (boxed: most rows are measured, and a large
    /// campaign keeps its rows).
    pub d_pcal: Option<Box<Row>>,
    /// d value / d θ over the effects' parameters (empty without effects; zero for the
    /// virtual rows of the second step, which hold the effects fixed).
    pub d_theta: Vec<f64>,
    /// The row's gains on the errors its setup's reset pose puts into every row of the
    /// setup ([`ResetGain`], [`share_reset`]); zero where the row reads no reset pose.
    pub reset_gain: ResetGain,
}

/// A row's gains on what its setup's reset pose read once for all its rows: the error of the
/// reading the instrument was zeroed on (x, y of a 2-D instrument; a single coordinate or ψ
/// in the first), then the errors of the reset pose's four encoders (the model adds the reset
/// pose's TCP, or subtracts its configuration, from every reading).
pub type ResetGain = nalgebra::SVector<f64, 6>;

/// The [`ResetGain`] of a row: `reading` on the instrument's zero, `reset` the row's
/// sensitivity to the reset pose's carrier positions.
pub(super) fn reset_gain(reading: Vector2<f64>, reset: &[f64; 4]) -> ResetGain {
    ResetGain::from_column_slice(&[reading.x, reading.y, reset[0], reset[1], reset[2], reset[3]])
}

/// A row's value without its derivatives: what a fit keeps of its rows (the statistics,
/// the noise estimation and the diagnosis read these; a campaign of 10⁵ poses keeps them in
/// a fifth of the memory of its [`Residual`]s).
#[derive(Clone, Debug)]
pub struct RowValue {
    pub pose: usize,
    pub instrument: Instrument,
    pub direction: Direction,
    /// W_mod − W_meas (mm or rad).
    pub value: f64,
    /// Standard deviation of the row (mm or rad).
    pub sigma: f64,
    /// Its variance split by noise group.
    pub parts: Parts,
}

impl From<&Residual> for RowValue {
    fn from(r: &Residual) -> RowValue {
        RowValue {
            pose: r.pose,
            instrument: r.instrument,
            direction: r.direction,
            value: r.value,
            sigma: r.sigma,
            parts: r.parts,
        }
    }
}

/// A pose the model could not evaluate, with its source line.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{source}:{line}: {instrument} pose: {error}")]
pub struct PoseError {
    pub source: String,
    pub line: usize,
    pub instrument: &'static str,
    #[source]
    pub error: ModelError,
}

/// Why the model could not evaluate a pose: its geometry, or (for a drive-force row) the
/// elastic equilibrium.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    #[error(transparent)]
    Elastic(#[from] ElasticError),
}

impl PoseError {
    /// The error `error` of `pose` in `campaign`, located by its file and line.
    pub fn at(campaign: &Campaign, pose: &MeasuredPose, error: impl Into<ModelError>) -> PoseError {
        PoseError {
            source: campaign.source.clone(),
            line: pose.line,
            instrument: pose.instrument.as_str(),
            error: error.into(),
        }
    }
}
