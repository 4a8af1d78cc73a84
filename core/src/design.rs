//! Measurement campaigns of the spec as planned poses (spec "Workspace and measurement
//! campaigns", thesis 4.2-4.4).
//!
//! A design is the list of target TCP positions a campaign visits, grouped in setups, with the
//! reset pose of each relative setup marked. Designs are pure data: the digital twin
//! (`rpkm-twin`) drives them on a simulated machine, a real cell drives them on the machine.
//! Every target lies in the workspace x ∈ [−150, 150] mm, y ∈ [700, 2700] mm
//! ([`clamp_to_workspace`]).
//!
//! Ordering convention: within a setup the reset pose comes first (the instrument is zeroed
//! there, then the points are measured), and a point that coincides with the reset pose is not
//! measured twice.

use crate::campaign::Instrument;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Workspace bounds along x, mm.
pub const X_RANGE: (f64, f64) = (-150.0, 150.0);
/// Workspace bounds along y, mm.
pub const Y_RANGE: (f64, f64) = (700.0, 2700.0);
/// Centre of the workspace, mm.
pub const CENTRE: (f64, f64) = (0.0, 1700.0);

/// One planned pose of a campaign.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlannedPose {
    /// Setup id; relative measurements share their setup's reset pose.
    pub setup: String,
    /// Instrument measuring this pose.
    pub instrument: Instrument,
    /// Whether this is the reset pose of its setup (measured value 0, ball-bar pivot).
    pub reset: bool,
    /// Target TCP x, mm.
    pub x: f64,
    /// Target TCP y, mm.
    pub y: f64,
    /// Drives in follower mode while the pose is measured (`follower[i]` for q(i+1), the
    /// campaign's column): q2, q3 for self-calibration ([`FOLLOWERS_23`]); for an external
    /// instrument the mode the plan measures in, all four drives active where none follows
    /// (the spec's empty column).
    #[serde(default)]
    pub follower: [bool; 4],
}

/// q2 and q3 in follower mode, q1 and q4 position-controlled: self-calibration's mode, and
/// the mode an external instrument measures in where the model carries no preload.
pub const FOLLOWERS_23: [bool; 4] = [false, true, true, false];

impl PlannedPose {
    /// A pose of `setup` in the instrument's own mode: q2, q3 following for
    /// self-calibration, all drives active for any other.
    pub fn new(setup: &str, instrument: Instrument, reset: bool, (x, y): (f64, f64)) -> Self {
        PlannedPose {
            setup: setup.to_owned(),
            instrument,
            reset,
            x,
            y,
            follower: if instrument == Instrument::SelfCal {
                FOLLOWERS_23
            } else {
                [false; 4]
            },
        }
    }
}

/// Clamp a target into the workspace.
pub fn clamp_to_workspace(x: f64, y: f64) -> (f64, f64) {
    (x.clamp(X_RANGE.0, X_RANGE.1), y.clamp(Y_RANGE.0, Y_RANGE.1))
}

/// `n` evenly spaced values from `a` to `b` inclusive (`n ≥ 2`; `n == 1` gives the midpoint).
fn linspace(a: f64, b: f64, n: usize) -> impl Iterator<Item = f64> {
    let step = if n > 1 { (b - a) / (n - 1) as f64 } else { 0.0 };
    (0..n).map(move |k| {
        if n == 1 {
            0.5 * (a + b)
        } else {
            a + step * k as f64
        }
    })
}

/// Values from `a` to `b` with a raster `step` (the last value is `b` when it falls on the
/// raster within 1e-9 mm).
fn raster(a: f64, b: f64, step: f64) -> impl Iterator<Item = f64> {
    let n = crate::convert::floor_count((b - a) / step + 1e-9) + 1;
    (0..n).map(move |k| a + step * k as f64)
}

fn pose(setup: &str, instrument: Instrument, reset: bool, x: f64, y: f64) -> PlannedPose {
    PlannedPose::new(setup, instrument, reset, clamp_to_workspace(x, y))
}

/// A setup: reset pose first, then the points (a point equal to the reset pose is skipped).
fn setup(
    out: &mut Vec<PlannedPose>,
    id: &str,
    instrument: Instrument,
    reset: (f64, f64),
    points: impl IntoIterator<Item = (f64, f64)>,
) {
    out.push(pose(id, instrument, true, reset.0, reset.1));
    for (x, y) in points {
        if (x - reset.0).abs() < 1e-9 && (y - reset.1).abs() < 1e-9 {
            continue;
        }
        out.push(pose(id, instrument, false, x, y));
    }
}

/// Laser tracker: one setup `lt`, reset at the workspace centre, 5 x × 9 y grid over the
/// workspace (45 poses, the centre being the reset pose).
pub fn lt() -> Vec<PlannedPose> {
    let mut out = Vec::new();
    let grid: Vec<(f64, f64)> = linspace(Y_RANGE.0, Y_RANGE.1, 9)
        .flat_map(|y| linspace(X_RANGE.0, X_RANGE.1, 5).map(move |x| (x, y)))
        .collect();
    setup(&mut out, "lt", Instrument::Lt, CENTRE, grid);
    out
}

/// Side of the grid-encoder square, mm.
pub const KGM_SQUARE_MM: f64 = 140.0;

/// Grid encoder: 16 setups (8 y positions × 2 x positions, x = ±75 mm), each reset at its
/// centre and measuring the 9 points (3 × 3) of a 140 mm square around it (9 poses a setup).
pub fn kgm() -> Vec<PlannedPose> {
    let h = KGM_SQUARE_MM / 2.0;
    let mut out = Vec::new();
    for (iy, yc) in linspace(Y_RANGE.0 + h, Y_RANGE.1 - h, 8).enumerate() {
        for (ix, xc) in [-75.0, 75.0].into_iter().enumerate() {
            let pts: Vec<(f64, f64)> = [-h, 0.0, h]
                .into_iter()
                .flat_map(|dy| [-h, 0.0, h].into_iter().map(move |dx| (xc + dx, yc + dy)))
                .collect();
            setup(
                &mut out,
                &format!("kgm{}{}", iy + 1, ix + 1),
                Instrument::Kgm,
                (xc, yc),
                pts,
            );
        }
    }
    out
}

/// Double ball-bar length, mm.
pub const DBB_LENGTH_MM: f64 = 150.0;

/// Double ball-bar: 8 setups along y at x = 0, the pivot at the reset TCP, 37 points (every
/// 10°, the first repeated at 360°) on the 150 mm circle (38 poses a setup).
pub fn dbb() -> Vec<PlannedPose> {
    let r = DBB_LENGTH_MM;
    let mut out = Vec::new();
    for (k, yc) in linspace(Y_RANGE.0 + r, Y_RANGE.1 - r, 8).enumerate() {
        let pts = circle_points(0.0, yc, r, 37);
        setup(
            &mut out,
            &format!("dbb{}", k + 1),
            Instrument::Dbb,
            (0.0, yc),
            pts,
        );
    }
    out
}

fn circle_points(xc: f64, yc: f64, r: f64, n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / (n - 1) as f64;
            (xc + r * a.cos(), yc + r * a.sin())
        })
        .collect()
}

/// Laser interferometer along x: lines along x every 15 mm (21 points) at 9 y positions, one
/// setup per line, reset at the line's first point.
pub fn li_x() -> Vec<PlannedPose> {
    let mut out = Vec::new();
    for (k, y) in linspace(Y_RANGE.0, Y_RANGE.1, 9).enumerate() {
        let pts: Vec<(f64, f64)> = raster(X_RANGE.0, X_RANGE.1, 15.0).map(|x| (x, y)).collect();
        setup(
            &mut out,
            &format!("lix{}", k + 1),
            Instrument::LiX,
            pts[0],
            pts.clone(),
        );
    }
    out
}

/// Laser interferometer along y: lines along y every 25 mm (81 points) at 13 x positions, one
/// setup per line, reset at the line's first point.
pub fn li_y() -> Vec<PlannedPose> {
    let mut out = Vec::new();
    for (k, x) in linspace(X_RANGE.0, X_RANGE.1, 13).enumerate() {
        let pts: Vec<(f64, f64)> = raster(Y_RANGE.0, Y_RANGE.1, 25.0).map(|y| (x, y)).collect();
        setup(
            &mut out,
            &format!("liy{}", k + 1),
            Instrument::LiY,
            pts[0],
            pts.clone(),
        );
    }
    out
}

/// Platform angle (LI angle optics): one setup of 28 y positions at x = 0, and one setup for
/// each of 3 y positions (700, 1700, 2700 mm) of 21 x positions (15 mm raster). The angle is
/// relative: each setup resets at its first point.
pub fn li_psi() -> Vec<PlannedPose> {
    let mut out = Vec::new();
    let along_y: Vec<(f64, f64)> = linspace(Y_RANGE.0, Y_RANGE.1, 28)
        .map(|y| (0.0, y))
        .collect();
    setup(
        &mut out,
        "lipsi_y",
        Instrument::LiPsi,
        along_y[0],
        along_y.clone(),
    );
    for y in [Y_RANGE.0, CENTRE.1, Y_RANGE.1] {
        let pts: Vec<(f64, f64)> = linspace(X_RANGE.0, X_RANGE.1, 21).map(|x| (x, y)).collect();
        setup(
            &mut out,
            &format!("lipsi_x{y:.0}"),
            Instrument::LiPsi,
            pts[0],
            pts.clone(),
        );
    }
    out
}

/// Self-calibration (q2, q3 followers, no reset): lines along x at y = 700, 1700, 2700 mm with a
/// 10, 5, 10 mm raster and one line along y at x = 0 with an 80 mm raster (149 poses).
pub fn self_cal() -> Vec<PlannedPose> {
    let mut out = Vec::new();
    for (y, step) in [(700.0, 10.0), (1700.0, 5.0), (2700.0, 10.0)] {
        for x in raster(X_RANGE.0, X_RANGE.1, step) {
            out.push(pose(
                &format!("self_x{y:.0}"),
                Instrument::SelfCal,
                false,
                x,
                y,
            ));
        }
    }
    for y in raster(Y_RANGE.0, Y_RANGE.1, 80.0) {
        out.push(pose("self_y", Instrument::SelfCal, false, 0.0, y));
    }
    out
}

/// Radius of the circular test, mm.
pub const CIRCLE_RADIUS_MM: f64 = 100.0;

/// Circular test: the ball-bar pivot at the workspace centre (the reset pose), then a
/// programmed circle of radius 100 mm, 73 points (every 5°, the first repeated at 360°).
pub fn circle() -> Vec<PlannedPose> {
    let mut out = Vec::new();
    let pts = circle_points(CENTRE.0, CENTRE.1, CIRCLE_RADIUS_MM, 73);
    setup(&mut out, "circle", Instrument::Circle, CENTRE, pts);
    out
}

/// Held-out validation: one laser-tracker setup `val`, reset at the workspace centre, then `n`
/// poses drawn uniformly over the workspace from `seed`.
pub fn validation(n: usize, seed: u64) -> Vec<PlannedPose> {
    let mut rng = StdRng::seed_from_u64(seed);
    let pts: Vec<(f64, f64)> = (0..n)
        .map(|_| {
            (
                rng.gen_range(X_RANGE.0..=X_RANGE.1),
                rng.gen_range(Y_RANGE.0..=Y_RANGE.1),
            )
        })
        .collect();
    let mut out = Vec::new();
    setup(&mut out, "val", Instrument::Lt, CENTRE, pts);
    out
}

/// Production: `n` poses drawn uniformly over the workspace from `seed`, all four drives
/// position-controlled and no instrument (`none`): what a machine visits while it works. Its
/// drive forces are its only measurements.
pub fn production(n: usize, seed: u64) -> Vec<PlannedPose> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let x = rng.gen_range(X_RANGE.0..=X_RANGE.1);
            let y = rng.gen_range(Y_RANGE.0..=Y_RANGE.1);
            pose("production", Instrument::None, false, x, y)
        })
        .collect()
}

/// Random targets in small setups, the class of design of the foreign simulator's campaigns
/// (`../shared/campaigns/foreign`): `setups` setups of `poses` poses of `instrument`, each
/// target drawn uniformly over the workspace from `seed` (a grid encoder's within its square
/// around the setup's reset pose, which a relative instrument's setup starts with and
/// counts among its poses). Setup ids are the instrument's name and the setup's number. A
/// campaign of many such setups is what a calibration's cost must not follow: its cost is
/// per pose, not per setup (issue 30).
pub fn random_setups(
    instrument: Instrument,
    setups: usize,
    poses: usize,
    seed: u64,
) -> Vec<PlannedPose> {
    let mut rng = StdRng::seed_from_u64(seed);
    let anywhere = |rng: &mut StdRng| {
        (
            rng.gen_range(X_RANGE.0..=X_RANGE.1),
            rng.gen_range(Y_RANGE.0..=Y_RANGE.1),
        )
    };
    let mut out = Vec::with_capacity(setups * poses);
    for k in 0..setups {
        let id = format!("{}{k:04}", instrument.as_str());
        let reset = anywhere(&mut rng);
        let resets = instrument.takes_reset();
        if resets {
            out.push(pose(&id, instrument, true, reset.0, reset.1));
        }
        for _ in usize::from(resets)..poses {
            let (x, y) = if instrument == Instrument::Kgm {
                let h = KGM_SQUARE_MM / 2.0;
                (
                    reset.0 + rng.gen_range(-h..=h),
                    reset.1 + rng.gen_range(-h..=h),
                )
            } else {
                anywhere(&mut rng)
            };
            out.push(pose(&id, instrument, false, x, y));
        }
    }
    out
}

/// The 231-point evaluation grid (11 x × 21 y, row-major in y) of sensitivity and
/// observability studies.
pub fn grid_231() -> Vec<(f64, f64)> {
    linspace(Y_RANGE.0, Y_RANGE.1, 21)
        .flat_map(|y| linspace(X_RANGE.0, X_RANGE.1, 11).map(move |x| (x, y)))
        .collect()
}

/// The design of one instrument's campaign (the validation campaign uses
/// [`validation`]; `none` has no design and gives an empty list).
pub fn for_instrument(instrument: Instrument) -> Vec<PlannedPose> {
    match instrument {
        Instrument::Lt => lt(),
        Instrument::Kgm => kgm(),
        Instrument::Dbb => dbb(),
        Instrument::LiX => li_x(),
        Instrument::LiY => li_y(),
        Instrument::LiPsi => li_psi(),
        Instrument::SelfCal => self_cal(),
        Instrument::Circle => circle(),
        Instrument::None => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setups(d: &[PlannedPose]) -> Vec<(String, usize, usize)> {
        let mut out: Vec<(String, usize, usize)> = Vec::new();
        for p in d {
            match out.iter_mut().find(|s| s.0 == p.setup) {
                Some(s) => {
                    s.1 += 1;
                    s.2 += usize::from(p.reset);
                }
                None => out.push((p.setup.clone(), 1, usize::from(p.reset))),
            }
        }
        out
    }

    #[test]
    fn counts() {
        assert_eq!(lt().len(), 45);
        assert_eq!(setups(&kgm()).len(), 16);
        assert!(setups(&kgm()).iter().all(|s| s.1 == 9 && s.2 == 1));
        assert!(setups(&dbb()).iter().all(|s| s.1 == 38 && s.2 == 1));
        assert_eq!(li_x().len(), 9 * 21);
        assert_eq!(li_y().len(), 13 * 81);
        assert_eq!(li_psi().len(), 28 + 3 * 21);
        assert_eq!(self_cal().len(), 31 + 61 + 31 + 26);
        assert_eq!(grid_231().len(), 231);
        assert_eq!(validation(50, 1).len(), 51);
        let random_kgm = random_setups(Instrument::Kgm, 7, 9, 1);
        assert!(setups(&random_kgm).iter().all(|s| s.1 == 9 && s.2 == 1));
        assert_eq!(
            setups(&random_setups(Instrument::SelfCal, 3, 100, 1))[2],
            ("self0002".into(), 100, 0)
        );
        for d in [
            lt(),
            kgm(),
            dbb(),
            li_x(),
            li_y(),
            li_psi(),
            circle(),
            random_kgm,
        ] {
            for p in &d {
                assert_eq!(clamp_to_workspace(p.x, p.y), (p.x, p.y));
            }
        }
    }
}
