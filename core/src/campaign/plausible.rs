//! What a value of a campaign row may be: bounds far beyond the machine (a number past them is
//! a unit mix-up or a corrupted field, never a measurement), and reachability (the four rods
//! can close at the row's actuator positions).
//!
//! The bounds come from the spec's machine: workspace x ∈ [−150, 150] mm, y ∈ [700, 2700] mm,
//! guides at d = ±1460 mm, rods of 950 mm, so every actuator position and every relative TCP
//! displacement of a pose stays within about 3.7 m; the nominal drive force is 8,600 N. Each
//! bound is at least an order of magnitude past that, so no real file is refused, while 1e300
//! (which makes every σ of a calibration infinite) is.

use crate::elastic::NOMINAL_DRIVE_FORCE_N;
use crate::geometry::{self, GeometryError};
use crate::params::{Model, Params};

use super::write::number;

/// |q|, |x|, |y|, |r| in mm: 100 m, 25 times the machine's largest extent (about 3.7 m).
pub const LENGTH_MAX_MM: f64 = 1e5;
/// |f| in N: a thousand times the nominal drive force; the drives give a few times it.
pub const FORCE_MAX_N: f64 = 1e3 * NOMINAL_DRIVE_FORCE_N;
/// |ψ| relative to the reset pose, rad: a full turn; the platform's parasitic angle is
/// milliradians.
pub const ANGLE_MAX_RAD: f64 = std::f64::consts::TAU;
/// |t| in s, and any covariate: 1e10 (317 years in s), past every clock a campaign uses,
/// Unix time included (1.7e9 s), and small enough that squares in a regression stay finite.
pub const TIME_MAX_S: f64 = 1e10;
/// Largest |q2 − q2(q1, q4)|, |q3 − q3(q1, q4)| in mm against the nominal geometry. Real
/// machines are within a few mm of it (0.4 mm of incompatibility already drives a drive to
/// 100 % of its force, seed 4.4; follower-mode differences were 0.4-0.6 mm), so 100 mm means
/// a carrier the rods cannot hold, not a machine off its drawing.
pub const COMPATIBILITY_MAX_MM: f64 = 100.0;

/// The bound of a column's magnitude and its unit, by the column's name (covariates: any
/// name that is not a required column).
pub fn bound(name: &str) -> (f64, &'static str) {
    match name {
        "q1" | "q2" | "q3" | "q4" | "x" | "y" | "r" => (LENGTH_MAX_MM, "mm"),
        "f1" | "f2" | "f3" | "f4" => (FORCE_MAX_N, "N"),
        "psi" => (ANGLE_MAX_RAD, "rad"),
        "t" => (TIME_MAX_S, "s"),
        _ => (TIME_MAX_S, ""),
    }
}

/// Why the machine cannot take a row's actuator positions: which actuator to blame (0-based)
/// and a sentence for people.
#[derive(Debug, Clone, PartialEq)]
pub struct Unreachable {
    /// 0-based actuator (q1 is 0).
    pub actuator: usize,
    /// Why, for people.
    pub why: String,
}

/// Checks that the nominal machine can close its four rods at `q` (mm): (q1, q4) give the
/// platform pose (model 24: the spec's reference forward model, analytic start, no rod 5),
/// and q2, q3 lie within [`COMPATIBILITY_MAX_MM`] of what rods 2 and 3 need there.
pub fn reachable(q: [f64; 4]) -> Result<(), Unreachable> {
    let p = Params::nominal();
    let [q2, q3] = geometry::rgm(&p, Model::M24, q[0], q[3]).map_err(|e| Unreachable {
        actuator: blame_of_pair(&p, q),
        why: format!(
            "with q1 = {} mm and q4 = {} mm the nominal machine has no pose: {}",
            number(q[0]),
            number(q[3]),
            geometry_reason(&e)
        ),
    })?;
    for (k, need) in [(1, q2), (2, q3)] {
        let off = q[k] - need;
        if off.abs() > COMPATIBILITY_MAX_MM {
            return Err(Unreachable {
                actuator: k,
                why: format!(
                    "rod {} needs q{} = {need:.3} mm at the pose of q1, q4, this is {off:.3} mm \
                     off, expected within {COMPATIBILITY_MAX_MM} mm",
                    k + 1,
                    k + 1,
                ),
            });
        }
    }
    Ok(())
}

/// Which of q1, q4 to blame when rods 1 and 4 cannot close: the one farther outside the
/// range it spans over the workspace (q1 when both are inside).
fn blame_of_pair(p: &Params, q: [f64; 4]) -> usize {
    let mut range = [[f64::INFINITY, f64::NEG_INFINITY]; 4];
    for x in [-150.0, 150.0] {
        for y in [700.0, 2700.0] {
            if let Ok(s) = geometry::igm(p, Model::M24, x, y) {
                for (r, v) in range.iter_mut().zip(s.q()) {
                    *r = [r[0].min(v), r[1].max(v)];
                }
            }
        }
    }
    let outside = |a: usize| (range[a][0] - q[a]).max(q[a] - range[a][1]).max(0.0);
    if outside(3) > outside(0) {
        3
    } else {
        0
    }
}

/// The geometry's reason without its figures in mm² (which mean little to a reader of a CSV).
fn geometry_reason(e: &GeometryError) -> String {
    match e {
        GeometryError::NoIntersection { a, b, .. } => format!("rods {a} and {b} do not meet"),
        GeometryError::Unreachable { rod, .. } => format!("rod {rod} cannot reach its guide"),
        other => other.to_string(),
    }
}
