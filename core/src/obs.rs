//! Model values of the measurements (thesis 4.2.1.1 and 4.3.1): for each pose of a campaign
//! the rows the calibration compares, W_mod − W_meas, with their analytic Jacobian rows.
//!
//! - Laser tracker, grid encoder (inverse calibration, eq. 4.30): Q = igm(X_meas + fgm(Q_nr,reset, P), P),
//!   compared with all four recorded actuator positions.
//! - Ball-bar (eq. 4.31), interferometer x/y, platform angle (forward calibration): the distance
//!   to the pivot, the coordinate or ψ relative to the reset pose, through each of the
//!   non-redundant subsystems (q1, q4) and (q3, q4) ("multiple use of the same data").
//! - Their second step (eq. 4.32): q2 = igm(X_e, P) from virtual measurements X_e = fgm(Q_nr, P_cal).
//! - Self-calibration (eq. 4.37): (q2, q3) = rgm(q1, q4, P) against the follower encoders.
//!
//! Each row carries its own standard deviation: the instrument noise of `noise` propagated
//! through the model's local derivatives (task-variable scaling, eq. 3.22).

use crate::campaign::{Campaign, Instrument, Pose};
use crate::geometry::{self, q_var, GeometryError, Solution, Subsystem, PSI, X, Y};
use crate::noise;
use crate::params::{Model, Params, N_PARAMS};
use nalgebra::{SVector, Vector2};

/// A Jacobian row over the 29 parameters.
pub type Row = SVector<f64, N_PARAMS>;

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
        }
    }
}

impl Direction {
    /// Unit of the row's residual: mm, or rad for ψ.
    pub fn is_angle(self) -> bool {
        matches!(self, Direction::Psi(..))
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
    /// d value / d p over the 29 parameters.
    pub jacobian: Row,
    /// For virtual rows of the second step: d value / d p_cal, the sensitivity to the
    /// first step's parameters that made the virtual measurement (to propagate their
    /// uncertainty); None for measured rows.
    pub d_pcal: Option<Row>,
}

/// A pose the model could not evaluate, with its source line.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{source}:{line}: {instrument} pose: {error}")]
pub struct PoseError {
    pub source: String,
    pub line: usize,
    pub instrument: &'static str,
    #[source]
    pub error: GeometryError,
}

impl PoseError {
    /// The error `error` of `pose` in `campaign`, located by its file and line.
    pub fn at(campaign: &Campaign, pose: &Pose, error: GeometryError) -> PoseError {
        PoseError {
            source: campaign.source.clone(),
            line: pose.line,
            instrument: pose.instrument.as_str(),
            error,
        }
    }
}

/// The forward subsystems used by forward calibration rows (thesis 4.2.1).
pub const FORWARD_SUBSYSTEMS: [Subsystem; 2] =
    [Subsystem::Actuators(0, 3), Subsystem::Actuators(2, 3)];

/// A solved forward model with its parameter and actuator sensitivities.
struct Forward {
    sol: Solution,
    sens: geometry::Sensitivity,
}

fn forward(
    p: &Params,
    model: Model,
    sub: Subsystem,
    q: &[f64; 4],
) -> Result<Forward, GeometryError> {
    let Subsystem::Actuators(a, b) = sub else {
        unreachable!("forward rows use actuator subsystems")
    };
    let sol = geometry::solve(p, model, sub, [q[a], q[b]])?;
    let sens = geometry::sensitivity(p, model, sub, &sol)?;
    Ok(Forward { sol, sens })
}

/// Variance (mm² or rad²) that noise on the known actuators adds to configuration variable `v`.
fn encoder_variance(f: &Forward, v: usize) -> f64 {
    (f.sens.dc_dk[(v, 0)].powi(2) + f.sens.dc_dk[(v, 1)].powi(2)) * noise::ENCODER_MM.powi(2)
}

/// Which kinds of rows to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Direct rows of every instrument (inverse, forward, self-calibration).
    Direct,
    /// Second step of forward instruments: q2 from virtual measurements made with `p_cal`.
    VirtualQ2,
}

/// Rows of one campaign under parameters `p`. Reset poses of relative instruments give no
/// row of their own (their measured value is zero by definition); `circle` and `none` poses
/// give none (the circular test is an evaluation, not a calibration measurement).
pub fn residuals(
    campaign: &Campaign,
    p: &Params,
    model: Model,
    step: Step,
    p_cal: &Params,
) -> Result<Vec<Residual>, PoseError> {
    let mut out = Vec::with_capacity(campaign.poses.len() * 4);
    for setup in campaign.setups() {
        let reset = setup.reset.map(|i| (i, &campaign.poses[i]));
        for &i in &setup.poses {
            let pose = &campaign.poses[i];
            if pose.reset && pose.instrument.is_relative() {
                continue;
            }
            let err = |error| PoseError::at(campaign, pose, error);
            match step {
                Step::Direct => {
                    pose_rows(i, pose, reset.map(|r| r.1), p, model, &mut out).map_err(err)?
                }
                Step::VirtualQ2 => {
                    virtual_q2_row(i, pose, p, model, p_cal, &mut out).map_err(err)?
                }
            }
        }
        // the reset pose of a forward instrument still yields a virtual q2 measurement
        if step == Step::VirtualQ2 {
            if let Some((i, pose)) = reset {
                let err = |error| PoseError::at(campaign, pose, error);
                virtual_q2_row(i, pose, p, model, p_cal, &mut out).map_err(err)?;
            }
        }
    }
    Ok(out)
}

fn pose_rows(
    i: usize,
    pose: &Pose,
    reset: Option<&Pose>,
    p: &Params,
    model: Model,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    use Instrument::*;
    match (pose.instrument, reset) {
        (Lt | Kgm, Some(reset)) => inverse_rows(i, pose, reset, p, model, out),
        (Dbb | LiX | LiY | LiPsi, Some(reset)) => forward_rows(i, pose, reset, p, model, out),
        (SelfCal, _) => self_rows(i, pose, p, model, out),
        _ => Ok(()),
    }
}

/// Inverse calibration rows (eq. 4.30) of a laser-tracker or grid-encoder pose.
fn inverse_rows(
    i: usize,
    pose: &Pose,
    reset: &Pose,
    p: &Params,
    model: Model,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    let (Some(mx), Some(my)) = (pose.x, pose.y) else {
        return Ok(());
    };
    let r = forward(p, model, Subsystem::NR, &reset.q)?;
    let (x, y) = (mx + r.sol.c[X], my + r.sol.c[Y]);
    let inv = geometry::solve(p, model, Subsystem::Tcp, [x, y])?;
    let s = geometry::sensitivity(p, model, Subsystem::Tcp, &inv)?;
    let cov = noise::xy_covariance(pose.instrument, Vector2::new(x, y));
    for a in 0..4 {
        let v = q_var(a);
        // dq/dp = ∂igm/∂p + ∂igm/∂X · d fgm(Q_reset)/dp
        let mut jac: Row = s.dc_dp.row(v).transpose();
        jac += r.sens.dc_dp.row(X).transpose() * s.dc_dk[(v, 0)]
            + r.sens.dc_dp.row(Y).transpose() * s.dc_dk[(v, 1)];
        let g = Vector2::new(s.dc_dk[(v, 0)], s.dc_dk[(v, 1)]);
        let sigma = ((g.transpose() * cov * g)[0] + noise::ENCODER_MM.powi(2)).sqrt();
        out.push(Residual {
            pose: i,
            instrument: pose.instrument,
            direction: Direction::Q(a),
            value: inv.c[v] - pose.q[a],
            sigma,
            jacobian: jac,
            d_pcal: None,
        });
    }
    Ok(())
}

/// Forward calibration rows (eq. 4.31): relative distance, coordinate or angle through each
/// forward subsystem.
fn forward_rows(
    i: usize,
    pose: &Pose,
    reset: &Pose,
    p: &Params,
    model: Model,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    for sub in FORWARD_SUBSYSTEMS {
        let Subsystem::Actuators(a, b) = sub else {
            continue;
        };
        let now = forward(p, model, sub, &pose.q)?;
        let zero = forward(p, model, sub, &reset.q)?;
        let d = |v: usize| now.sol.c[v] - zero.sol.c[v];
        let dj = |v: usize| -> Row { (now.sens.dc_dp.row(v) - zero.sens.dc_dp.row(v)).transpose() };
        let var = |v: usize| encoder_variance(&now, v) + encoder_variance(&zero, v);
        let inst = pose.instrument;
        let sig = noise::scalar_sigma(inst);
        let (direction, value, jac, sigma) = match inst {
            Instrument::Dbb => {
                let Some(r) = pose.r else { return Ok(()) };
                let (dx, dy) = (d(X), d(Y));
                let dist = dx.hypot(dy);
                if dist < 1e-9 {
                    continue;
                }
                let (ux, uy) = (dx / dist, dy / dist);
                let jac = dj(X) * ux + dj(Y) * uy;
                let var_enc = ux * ux * var(X) + uy * uy * var(Y);
                (
                    Direction::R(a, b),
                    dist - r,
                    jac,
                    (sig * sig + var_enc).sqrt(),
                )
            }
            // one coordinate relative to the reset pose: x, y or ψ
            Instrument::LiX | Instrument::LiY | Instrument::LiPsi => {
                let (v, measured, direction) = match inst {
                    Instrument::LiX => (X, pose.x, Direction::X(a, b)),
                    Instrument::LiY => (Y, pose.y, Direction::Y(a, b)),
                    _ => (PSI, pose.psi, Direction::Psi(a, b)),
                };
                let Some(m) = measured else { return Ok(()) };
                (direction, d(v) - m, dj(v), (sig * sig + var(v)).sqrt())
            }
            _ => return Ok(()),
        };
        out.push(Residual {
            pose: i,
            instrument: inst,
            direction,
            value,
            sigma,
            jacobian: jac,
            d_pcal: None,
        });
    }
    Ok(())
}

/// Self-calibration rows (eq. 4.37): followers q2, q3 against rgm(q1, q4).
fn self_rows(
    i: usize,
    pose: &Pose,
    p: &Params,
    model: Model,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    let f = forward(p, model, Subsystem::NR, &pose.q)?;
    for a in [1, 2] {
        let v = q_var(a);
        let sigma = (noise::ENCODER_MM.powi(2) + encoder_variance(&f, v)).sqrt();
        out.push(Residual {
            pose: i,
            instrument: pose.instrument,
            direction: Direction::Q(a),
            value: f.sol.c[v] - pose.q[a],
            sigma,
            jacobian: f.sens.dc_dp.row(v).transpose(),
            d_pcal: None,
        });
    }
    Ok(())
}

/// Second step of the forward instruments (eq. 4.32): X_e = fgm(Q_nr, P_cal), q2 = igm(X_e, P).
fn virtual_q2_row(
    i: usize,
    pose: &Pose,
    p: &Params,
    model: Model,
    p_cal: &Params,
    out: &mut Vec<Residual>,
) -> Result<(), GeometryError> {
    use Instrument::*;
    if !matches!(pose.instrument, Dbb | LiX | LiY | LiPsi) {
        return Ok(());
    }
    let xe = geometry::fgm(p_cal, model, pose.q[0], pose.q[3])?;
    let xe_sens = geometry::sensitivity(p_cal, model, Subsystem::NR, &xe)?;
    let inv = geometry::igm(p, model, xe.x(), xe.y())?;
    let s = geometry::sensitivity(p, model, Subsystem::Tcp, &inv)?;
    let v = q_var(1);
    let d_pcal: Row = (xe_sens.dc_dp.row(X) * s.dc_dk[(v, 0)]
        + xe_sens.dc_dp.row(Y) * s.dc_dk[(v, 1)])
        .transpose();
    out.push(Residual {
        pose: i,
        instrument: pose.instrument,
        direction: Direction::VirtualQ2,
        value: inv.c[v] - pose.q[1],
        sigma: noise::ENCODER_MM * 2f64.sqrt(),
        jacobian: s.dc_dp.row(v).transpose(),
        d_pcal: Some(d_pcal),
    });
    Ok(())
}

/// Whether a campaign has rows of the given kind.
pub fn has_forward_instruments(campaign: &Campaign) -> bool {
    campaign.poses.iter().any(|p| {
        matches!(
            p.instrument,
            Instrument::Dbb | Instrument::LiX | Instrument::LiY | Instrument::LiPsi
        )
    })
}

/// TCP position error of held-out poses (µm-ready, mm here): for every non-reset pose of a
/// relative TCP instrument, the model's TCP from the recorded actuators (fgm of (q1, q4),
/// relative to the setup's reset pose) minus the instrument's reading, per measured coordinate
/// (x, y, or the ball-bar distance). Returns (pose index, coordinate name, error mm).
pub fn tcp_errors(
    campaign: &Campaign,
    p: &Params,
    model: Model,
) -> Result<Vec<(usize, &'static str, f64)>, PoseError> {
    let mut out = Vec::new();
    for setup in campaign.setups() {
        let Some(reset_i) = setup.reset else { continue };
        let reset = &campaign.poses[reset_i];
        for &i in &setup.poses {
            let pose = &campaign.poses[i];
            if pose.reset || !pose.instrument.is_relative() {
                continue;
            }
            let err = |error| PoseError::at(campaign, pose, error);
            let now = geometry::fgm(p, model, pose.q[0], pose.q[3]).map_err(err)?;
            let zero = geometry::fgm(p, model, reset.q[0], reset.q[3]).map_err(err)?;
            let (dx, dy) = (now.x() - zero.x(), now.y() - zero.y());
            if let Some(m) = pose.x {
                out.push((i, "x", dx - m));
            }
            if let Some(m) = pose.y {
                out.push((i, "y", dy - m));
            }
            if let Some(m) = pose.r {
                out.push((i, "r", dx.hypot(dy) - m));
            }
        }
    }
    Ok(out)
}
