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
//!
//! Physical effects ([`crate::effects`]) enter as per-pose corrections of the model's inputs
//! (parameters, carrier positions, recorded x/y); each row keeps its sensitivity to those
//! inputs so that the Jacobian over the effects' parameters is one chain rule
//! ([`Corrections::theta_row`]).
//!
//! Files, one job each:
//! - `row.rs`: What a row measures and holds: its direction, value, derivatives and noise
//!   parts, and the model's errors at a pose.
//! - `forward_solve.rs`: The forward solves behind a pose's rows: a subsystem's configuration
//!   under the effects' corrections, and its sensitivities.
//! - `context.rs`: What every row of one evaluation shares, and what every pose of a relative
//!   setup reads of its reset pose, solved once.
//! - `evaluation.rs`: One evaluation of a campaign's rows: the pieces across setups, the
//!   reset pose solved once, every pose's rows.
//! - `force.rs`: The drive-force rows (currents), their Jacobian and the force-position
//!   gains.
//! - `inverse.rs`: Inverse calibration rows (eq. 4.30) of a laser tracker or grid encoder,
//!   decorrelated through the drives' gains.
//! - `reset.rs`: What a setup's reset pose shares with all its rows: the covariance,
//!   marginalised out of the rows.
//! - `forward.rs`: Forward calibration rows (eq. 4.31), their second step (eq. 4.32) and
//!   self-calibration rows (eq. 4.37).
//! - `tcp.rs`: Held-out TCP errors of the relative instruments, with their sensitivities to
//!   the effects.
//! - `zero.rs`: Each setup's zero removed from the held-out TCP errors, and the variance
//!   left of their noise.

mod context;
mod evaluation;
mod force;
mod forward;
mod forward_solve;
mod inverse;
mod reset;
mod row;
mod tcp;
mod zero;

pub use crate::params::Row;
pub use evaluation::{residuals, residuals_in, residuals_with, Evaluation, Form, Pieces, Step};
pub use force::{force_jacobian, force_position_gains, force_residuals};
pub use forward_solve::FORWARD_SUBSYSTEMS;
pub use reset::zero_covariance;
pub use row::{Direction, ModelError, PoseError, ResetGain, Residual, RowValue};
pub use tcp::{has_forward_instruments, tcp_errors, tcp_errors_with, TcpDirection, TcpError};
pub(crate) use zero::group_sums;
pub use zero::{zero_groups, zero_removed, zero_removed_variance};
