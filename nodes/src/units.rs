//! Units between the core and the topics: the core works in mm, rad, N, s (the thesis's),
//! the ROS topics in SI (REP 103), a person reads µm, mrad and ms. The factors and their
//! named conversions are the core's ([`rpkm_core::units`], one definition for the whole
//! workspace), re-exported here.
//!
//! Below them, the adapters of the live messages: a node reads an ActuatorState's drive
//! positions into the core's mm with [`drive_positions_mm`] and writes the mm it computed into
//! a message with one `set_*_mm` call per message, never field by field (the campaign's
//! messages are adapted in `campaign_bag`, the Parameters message in `node::geometry`).

pub use rpkm_core::units::*;

use rpkm_msgs::{ActuatorState, PreloadStatus, TcpEstimate};

/// An ActuatorState's drive positions q1..q4 (m on the topic) in the core's mm.
pub fn drive_positions_mm(state: &ActuatorState) -> [f64; 4] {
    state.position.map(mm_from_m)
}

/// Drive positions q1..q4 in the core's mm into an ActuatorState (m).
pub fn set_drive_positions_mm(state: &mut ActuatorState, q_mm: [f64; 4]) {
    state.position = q_mm.map(m_from_mm);
}

/// A TCP position (x, y) and the rods' loop residuals |A_i − B_i| − l_i, all in the core's mm,
/// into a TcpEstimate (m); ψ is rad on both sides and stays the caller's.
pub fn set_tcp_position_mm(
    estimate: &mut TcpEstimate,
    (x_mm, y_mm): (f64, f64),
    loops_mm: [f64; 5],
) {
    estimate.x = m_from_mm(x_mm);
    estimate.y = m_from_mm(y_mm);
    estimate.loop_residuals = loops_mm.map(m_from_mm);
}

/// The followers' offsets from the rigid model, q2 and q3 in the core's mm, into a
/// PreloadStatus (m).
pub fn set_follower_offsets_mm(status: &mut PreloadStatus, [dq2_mm, dq3_mm]: [f64; 2]) {
    status.dq2 = m_from_mm(dq2_mm);
    status.dq3 = m_from_mm(dq3_mm);
}
