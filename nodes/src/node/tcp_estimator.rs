//! `tcp_estimator`: for every ActuatorState, the elasto-geometric TCP estimate
//! (`rpkm_core::elastic::fegm`, warm-started from the previous equilibrium) with the current
//! parameters, published as TcpEstimate with the state's stamp and seq.
//!
//! When the elastic solve fails (warm and cold start), the pose comes from the rigid forward
//! model of (q1, q4) and the message says so: `converged = false`, `iterations = 0`, rod and
//! drive forces 0, loop residuals those of the rigid pose (they show the incompatibility). A
//! state no model can solve gets no estimate; both cases are counted on /diagnostics.
//! Per sample nothing is allocated: static nalgebra types, a `Copy` message, zero-copy
//! publishing on iceoryx2.

use std::time::Duration;

use rpkm_core::elastic::{fegm, fegm_from, Equilibrium};
use rpkm_core::geometry::{self, carrier_joint, platform_joint};
use rpkm_core::params::{Model, RODS};
use rpkm_msgs::{ActuatorState, DiagnosticStatus, TcpEstimate};
use rpkm_transport::topic;

use super::{
    diagnostic_array, status, CommonArgs, Every, Geometry, Idle, NodeContext, GEOMETRY_KEYS,
    MM_PER_M,
};

/// Parameter keys of the node.
pub const KEYS: [&str; 2] = ["busy_poll_ms", "rt_priority"];

/// Counters of an [`Estimator`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EstimatorCounts {
    /// Estimates published.
    pub estimates: u64,
    /// Elastic solves that needed a cold start (the warm start failed or there was none).
    pub cold_starts: u64,
    /// Estimates from the rigid fallback.
    pub rigid_fallbacks: u64,
    /// States no model could solve (no estimate).
    pub unsolved: u64,
}

/// The estimator's state: the geometry and the previous equilibrium (warm start).
#[derive(Debug, Clone)]
pub struct Estimator {
    geometry: Geometry,
    previous: Option<Equilibrium>,
    /// Counters.
    pub counts: EstimatorCounts,
    /// The last elastic error, for /diagnostics.
    pub last_error: Option<String>,
}

impl Estimator {
    /// An estimator with `geometry`.
    pub fn new(geometry: Geometry) -> Self {
        Self {
            geometry,
            previous: None,
            counts: EstimatorCounts::default(),
            last_error: None,
        }
    }

    /// The current geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// Replaces the geometry (a new Parameters message); the next solve starts cold.
    pub fn set_geometry(&mut self, geometry: Geometry) {
        self.geometry = geometry;
        self.previous = None;
    }

    /// The estimate answering `state`, or `None` when neither the elastic nor the rigid model
    /// solves it.
    pub fn estimate(&mut self, state: &ActuatorState) -> Option<TcpEstimate> {
        let g = &self.geometry;
        let q = state.position.map(|p| p * MM_PER_M);
        let warm = self
            .previous
            .as_ref()
            .and_then(|prev| fegm_from(&g.params, &g.stiffness, q, state.follower, prev).ok());
        let solved = match warm {
            Some(eq) => Ok(eq),
            None => {
                self.counts.cold_starts += 1;
                fegm(&g.params, &g.stiffness, q, state.follower)
            }
        };
        let model = match g.model {
            Model::M24 => TcpEstimate::MODEL_24,
            Model::M29 => TcpEstimate::MODEL_29,
        };
        let mut est = TcpEstimate {
            stamp: state.stamp,
            seq: state.seq,
            model,
            ..Default::default()
        };
        match solved {
            Ok(eq) => {
                self.previous = Some(eq);
                est.x = eq.x / MM_PER_M;
                est.y = eq.y / MM_PER_M;
                est.psi = eq.psi;
                est.rod_forces = eq.rod_force;
                est.drive_forces = eq.drive_force;
                est.iterations = eq.iterations as u32;
                est.converged = true;
                est.loop_residuals = loop_residuals(g, &q, eq.x, eq.y, eq.psi);
            }
            Err(e) => {
                self.previous = None;
                self.last_error = Some(e.to_string());
                let Ok(rigid) = geometry::fgm(&g.params, g.model, q[0], q[3]) else {
                    self.counts.unsolved += 1;
                    return None;
                };
                self.counts.rigid_fallbacks += 1;
                est.x = rigid.x() / MM_PER_M;
                est.y = rigid.y() / MM_PER_M;
                est.psi = rigid.psi();
                est.converged = false;
                est.iterations = 0;
                est.loop_residuals = loop_residuals(g, &q, rigid.x(), rigid.y(), rigid.psi());
            }
        }
        self.counts.estimates += 1;
        Some(est)
    }

    /// The /diagnostics status of the estimator.
    pub fn status(&self, node: &str) -> DiagnosticStatus {
        let c = self.counts;
        let (level, message) = if c.unsolved > 0 || c.rigid_fallbacks > 0 {
            (
                DiagnosticStatus::WARN,
                format!(
                    "{} rigid fallbacks, {} unsolved states; last elastic error: {}",
                    c.rigid_fallbacks,
                    c.unsolved,
                    self.last_error.as_deref().unwrap_or("none")
                ),
            )
        } else {
            (
                DiagnosticStatus::OK,
                format!("{} estimates, all elastic solves converged", c.estimates),
            )
        };
        status(
            level,
            node,
            message,
            vec![
                ("estimates", c.estimates.to_string()),
                ("cold_starts", c.cold_starts.to_string()),
                ("rigid_fallbacks", c.rigid_fallbacks.to_string()),
                ("unsolved", c.unsolved.to_string()),
                ("parameters", self.geometry.source.clone()),
            ],
        )
    }
}

/// |A_i − B_i| − l_i of rods 1..5 at pose (x, y, ψ) (mm) and actuator readings `q` (mm), in m;
/// rod 5 is 0 for model 24.
fn loop_residuals(g: &Geometry, q: &[f64; 4], x: f64, y: f64, psi: f64) -> [f64; 5] {
    let mut out = [0.0; 5];
    let rods = match g.model {
        Model::M24 => 4,
        Model::M29 => 5,
    };
    for (slot, rod) in out.iter_mut().zip(&RODS[..rods]) {
        let a = platform_joint(&g.params, rod, x, y, psi);
        let b = carrier_joint(&g.params, rod, q[rod.actuator]);
        *slot = ((a - b).norm() - g.params[rod.l]) / MM_PER_M;
    }
    out
}

/// Runs the node until SIGINT/SIGTERM.
pub fn run(args: &CommonArgs) -> anyhow::Result<()> {
    let mut declared: Vec<&str> = KEYS.to_vec();
    declared.extend(GEOMETRY_KEYS);
    let ctx = NodeContext::open("tcp_estimator", args, &declared, None)?;
    let geometry = Geometry::from_params(&ctx.params)?;
    let follow = ctx
        .params
        .bool("follow_parameters", true)
        .map_err(super::bad_param)?;
    let busy = ctx
        .params
        .non_negative("busy_poll_ms", 0.0)
        .map_err(super::bad_param)?;
    let rt_priority = ctx.params.u64("rt_priority", 0).map_err(super::bad_param)?;
    let states = ctx.subscriber(&topic::ACTUATOR_STATE)?;
    let parameters = if follow {
        Some(ctx.subscriber(&topic::PARAMETERS)?)
    } else {
        None
    };
    let estimates = ctx.publisher(&topic::TCP_ESTIMATE)?;
    let diagnostics = ctx.publisher(&topic::DIAGNOSTICS)?;
    ctx.log(format!(
        "estimating with {} ({}), publishing on {:?}, subscribing on {:?}",
        geometry.source, geometry.model, ctx.output, ctx.input
    ));
    let mut est = Estimator::new(geometry);
    // After the ports exist (their shared memory is mapped, then locked).
    // Without the privilege the node still estimates, at normal priority, and says so.
    match super::realtime::set_fifo(rt_priority) {
        Ok(Some(note)) => ctx.log(format!("real-time: {note}")),
        Ok(None) => {}
        Err(e) => ctx.log(format!(
            "real-time scheduling not set, running at normal priority: {e}"
        )),
    }
    // Between samples the node sleeps until the publisher's wake-up; the 20 ms bound keeps
    // the parameter checks and reports going when no sample comes.
    let mut idle = Idle::new(
        Duration::from_secs_f64(busy * 1e-3),
        Duration::from_millis(20),
    );
    let mut report = Every::new(ctx.diagnostics_period()?);
    let mut check_parameters = Every::new(Duration::from_millis(20));
    while !super::shutdown::requested() {
        if let Some(sub) = &parameters {
            if check_parameters.due() {
                if let Some(msg) = sub.try_recv()? {
                    match est.geometry().updated(&msg) {
                        Ok(g) => {
                            ctx.log(format!("parameters updated from {}", g.source));
                            est.set_geometry(g);
                        }
                        Err(e) => ctx.log(format!("ignoring parameters: {e}")),
                    }
                }
            }
        }
        match states.try_recv()? {
            Some(state) => {
                if let Some(e) = est.estimate(&state) {
                    estimates.publish(&e)?;
                }
                idle.worked();
            }
            None => {
                if report.due() {
                    diagnostics.publish(&diagnostic_array(est.status(&ctx.name)))?;
                }
                idle.wait_for(&states)?;
            }
        }
    }
    ctx.log("stopping");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rpkm_core::elastic::{Stiffness, ALL_ACTIVE};
    use rpkm_core::geometry::igm;
    use rpkm_core::params::Params;

    fn geometry() -> Geometry {
        Geometry {
            params: Params::nominal(),
            model: Model::M29,
            stiffness: Stiffness::default(),
            source: "test".into(),
        }
    }

    fn state(q_mm: [f64; 4], seq: u64) -> ActuatorState {
        ActuatorState {
            seq,
            position: q_mm.map(|q| q / MM_PER_M),
            ..Default::default()
        }
    }

    #[test]
    fn estimate_matches_the_core_and_warm_starts() -> Result<(), Box<dyn std::error::Error>> {
        let p = Params::nominal();
        let mut q = igm(&p, Model::M29, 20.0, 1650.0)?.q();
        q[2] += 0.05; // a little preload on q3
        let mut est = Estimator::new(geometry());
        let first = est.estimate(&state(q, 7)).ok_or("no estimate")?;
        let truth = fegm(
            &p,
            &Stiffness::default(),
            q.map(|v| v / MM_PER_M * MM_PER_M),
            ALL_ACTIVE,
        )?;
        assert_eq!(first.seq, 7);
        assert!(first.converged);
        assert!((first.x - truth.x / MM_PER_M).abs() < 1e-12);
        assert!((first.y - truth.y / MM_PER_M).abs() < 1e-12);
        for i in 0..4 {
            assert!((first.drive_forces[i] - truth.drive_force[i]).abs() < 1e-6);
        }
        // rod elongation = force / stiffness
        for i in 0..5 {
            let expect = truth.rod_force[i] / Stiffness::default().rod[i] / MM_PER_M;
            assert!(
                (first.loop_residuals[i] - expect).abs() < 1e-12,
                "rod {}",
                i + 1
            );
        }
        let second = est.estimate(&state(q, 8)).ok_or("no estimate")?;
        assert!(second.iterations < first.iterations, "warm start");
        assert_eq!(est.counts.cold_starts, 1);
        Ok(())
    }

    #[test]
    fn unreachable_state_gives_no_estimate_and_is_counted() {
        let mut est = Estimator::new(geometry());
        assert!(est.estimate(&state([1e5, 0.0, 0.0, -1e5], 1)).is_none());
        assert_eq!(est.counts.unsolved, 1);
        assert_eq!(est.status("e").level, DiagnosticStatus::WARN);
    }
}
