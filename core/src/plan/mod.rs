//! What to measure next (issue 28): from what a campaign already determines, the poses,
//! instruments and setups that determine most of what is left, and the poses and moves that
//! separate two explanations that tie.
//!
//! Everything is in the calibration's units of belief: the unknowns' columns scaled by their
//! manufacturing tolerance (the prior of [`crate::calib::Selection::Prior`]), the rows by
//! their σ. In those units the prior is the identity and the campaign's information G =
//! T JᵀΣ⁻¹J T; a combination is *determined* where G's eigenvalue exceeds 1 (the data pin it
//! better than the tolerance), as [`crate::calib::Calibration::determined`] counts.
//!
//! - [`candidates`]: the setups an engineer can mount (instrument, reset pose, the points in
//!   its travel and range); a setup whose instrument was zeroed on a reading ends with a
//!   return to its reset pose, the drift check ([`crate::returns`]).
//! - [`accuracy`]: the poses that lower the TCP's expected held-out RMS ([`forecast`]: over
//!   the workspace grid or the poses the user gives) most per pose spent, each relative
//!   setup's shared zero counted; what the same number of random poses would give.
//! - [`determine`]: greedy Bayesian D-optimal choice, ln det(I + G) per pose spent, a setup's
//!   reset and return poses paid when the setup is opened, then an exchange pass.
//! - [`mode`]: the drives' mode the external instruments measure in (the campaign's, all
//!   active only where the model carries the preload).
//! - [`separate`]: T-optimal discrimination of two hypotheses (a lost motion `dir_qN`, a
//!   parameter): the next poses where their predictions, after the geometry has absorbed
//!   what it can, differ most against the noise.
//! - [`worth`]: whether a plan for the TCP pays: the TCP's own error above the readings'
//!   noise, lower by [`WORTH`] of itself.
//! - [`csv`]: PLAN.csv, the campaign grammar without measured values.

pub mod accuracy;
pub mod csv;
pub mod forecast;
mod greedy;
pub mod mode;
pub mod separate;
mod start;
mod types;
pub mod worth;

pub use accuracy::{AccuracyPlanner, Forecast};
pub use forecast::TargetForecast;
pub use greedy::{condition_exchange, determine, normalized_condition, Chosen};
pub use mode::{drive_mode, DriveMode, DriveModeReason, Preload};
pub use start::{design_rows, Start};
pub use types::{
    returns_to_zero, CandidateSetup, Determination, DeterminationPlan, PlanError, PlannedSetup,
    Unknowns,
};
pub use worth::{own_error, WORTH};

use crate::analysis::{self};
use crate::campaign::Instrument;
use crate::design::{self, PlannedPose, CENTRE, DBB_LENGTH_MM, KGM_SQUARE_MM};
use crate::noise::NoiseModel;
use crate::obs::Residual;
use crate::observability::{condition_number, normalize_columns};
use crate::params::{Model, Params};
use nalgebra::DMatrix;

/// Ball-bar points per candidate circle (every 10°, as the thesis's circles).
const DBB_POINTS: usize = 36;
/// Grid-encoder candidate centres along y (every 133 mm: the spec's 8 centres among them).
const KGM_CENTRES_Y: usize = 15;

/// The candidate setups of `instruments`: the tracker and the angle optics reset at the
/// workspace centre over the 231-point grid; grid-encoder discs at 3 × 15 centres, each with
/// the 5 × 5 points of its 140 mm square; ball-bar circles (150 mm) at 9 pivots along y;
/// self-calibration (q2, q3 followers, no reset) on the grid.
pub fn candidates(instruments: &[Instrument]) -> Result<Vec<CandidateSetup>, PlanError> {
    let grid = design::grid_231();
    let off_centre: Vec<(f64, f64)> = grid
        .iter()
        .copied()
        .filter(|&(x, y)| (x - CENTRE.0).abs() > 1e-9 || (y - CENTRE.1).abs() > 1e-9)
        .collect();
    let mut out = Vec::new();
    for &inst in instruments {
        match inst {
            Instrument::Lt | Instrument::LiPsi => out.push(CandidateSetup {
                id: format!("plan_{}", inst.as_str()),
                instrument: inst,
                reset: Some(CENTRE),
                points: off_centre.clone(),
                returns: returns_to_zero(inst),
            }),
            Instrument::SelfCal => out.push(CandidateSetup {
                id: "plan_self".to_owned(),
                instrument: inst,
                reset: None,
                points: grid.clone(),
                returns: false,
            }),
            Instrument::Kgm => out.extend(kgm_candidates()),
            Instrument::Dbb => out.extend(dbb_candidates()),
            other => return Err(PlanError::NoCandidates(other)),
        }
    }
    Ok(out)
}

fn spaced(a: f64, b: f64, n: usize) -> impl Iterator<Item = f64> {
    (0..n).map(move |k| a + (b - a) * k as f64 / (n - 1) as f64)
}

fn kgm_candidates() -> Vec<CandidateSetup> {
    let h = KGM_SQUARE_MM / 2.0;
    let (y0, y1) = (design::Y_RANGE.0 + h, design::Y_RANGE.1 - h);
    let mut out = Vec::new();
    for (iy, yc) in spaced(y0, y1, KGM_CENTRES_Y).enumerate() {
        for (ix, xc) in [-75.0, 0.0, 75.0].into_iter().enumerate() {
            let points = spaced(-h, h, 5)
                .flat_map(|dy| spaced(-h, h, 5).map(move |dx| (xc + dx, yc + dy)))
                .filter(|&(x, y)| (x - xc).abs() > 1e-9 || (y - yc).abs() > 1e-9)
                .collect();
            out.push(CandidateSetup {
                id: format!("plan_kgm{}_{}", iy + 1, ix + 1),
                instrument: Instrument::Kgm,
                reset: Some((xc, yc)),
                points,
                returns: true,
            });
        }
    }
    out
}

fn dbb_candidates() -> Vec<CandidateSetup> {
    let r = DBB_LENGTH_MM;
    let (y0, y1) = (design::Y_RANGE.0 + r, design::Y_RANGE.1 - r);
    spaced(y0, y1, 9)
        .enumerate()
        .map(|(k, yc)| CandidateSetup {
            id: format!("plan_dbb{}", k + 1),
            instrument: Instrument::Dbb,
            reset: Some((0.0, yc)),
            points: (0..DBB_POINTS)
                .map(|j| {
                    let a = std::f64::consts::TAU * j as f64 / DBB_POINTS as f64;
                    (r * a.cos(), yc + r * a.sin())
                })
                .collect(),
            returns: false,
        })
        .collect()
}

/// `design` with its external-instrument poses measured in `mode` (self-calibration keeps
/// q2, q3 following).
pub fn measured_in(mut design: Vec<PlannedPose>, mode: &DriveMode) -> Vec<PlannedPose> {
    for p in design
        .iter_mut()
        .filter(|p| p.instrument != Instrument::SelfCal)
    {
        p.follower = mode.follower;
    }
    design
}

/// Each point of a candidate setup as a block of the information's square root (its rows,
/// in units of σ and tolerance; empty where the point gives no row).
pub fn point_blocks(
    setup: &CandidateSetup,
    p: &Params,
    model: Model,
    noise: &NoiseModel,
    unknowns: &Unknowns,
) -> Result<Vec<DMatrix<f64>>, PlanError> {
    let all: Vec<usize> = (0..setup.points.len()).collect();
    let rows = design_rows(&setup.design(&all), p, model, noise)?;
    let first = usize::from(setup.reset.is_some());
    Ok((0..setup.points.len())
        .map(|k| {
            let mine: Vec<&Residual> = rows.iter().filter(|r| r.pose == k + first).collect();
            unknowns.block(&mine)
        })
        .collect())
}

/// The plan of `budget` poses with `instruments` that determines most of what the campaign
/// of `start` left undetermined on `unknowns`.
pub fn plan_determination(
    start: &Start,
    unknowns: &Unknowns,
    instruments: &[Instrument],
    budget: usize,
) -> Result<DeterminationPlan, PlanError> {
    let g0 = start.information(unknowns)?;
    let setups = candidates(instruments)?;
    let blocks = setups
        .iter()
        .map(|s| point_blocks(s, start.params, start.model, start.noise, unknowns))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(determine(&g0, &setups, &blocks, budget))
}

/// A plan from no campaign of as many poses as `design`, with its instruments, for
/// `unknowns`, at parameters `p`: what the planner makes of the budget a design spent
/// (greedy D-optimal, then exchanged for the condition number, as the thesis rates its
/// designs; no setup returns to its reset, as none of the thesis's does).
pub fn plan_like(
    design: &[PlannedPose],
    p: &Params,
    model: Model,
    noise: &NoiseModel,
    unknowns: &Unknowns,
) -> Result<DeterminationPlan, PlanError> {
    let mut instruments: Vec<Instrument> = Vec::new();
    for d in design {
        if !instruments.contains(&d.instrument) {
            instruments.push(d.instrument);
        }
    }
    // like the thesis's designs, no setup returns to its reset: the same poses to spend
    let mut setups = candidates(&instruments)?;
    for s in &mut setups {
        s.returns = false;
    }
    let blocks = setups
        .iter()
        .map(|s| point_blocks(s, p, model, noise, unknowns))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(condition_exchange(&setups, &blocks, design.len()))
}

/// Condition number of the column-normalised weighted Jacobian of `rows` over `ids` (the
/// thesis's "condition number of the normalized Jacobian matrix", eq. 3.26).
pub fn condition(rows: &[Residual], ids: &[usize]) -> f64 {
    condition_number(&normalize_columns(&analysis::jacobian(rows, ids, true)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;

    /// Eigenvalues 4, 0.5 and 0: one combination pinned better than its tolerance, and
    /// 4/5 + 0.5/1.5 effective.
    #[test]
    fn determination_counts_eigenvalues_above_one() {
        let g = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 0.5, 0.0]));
        let d = Determination::of(&g);
        assert_eq!((d.determined, d.of), (1, 3));
        assert!((d.effective - (0.8 + 1.0 / 3.0)).abs() < 1e-12);
    }

    fn setup(id: &str, reset: bool, n: usize) -> CandidateSetup {
        CandidateSetup {
            id: id.to_owned(),
            instrument: Instrument::Lt,
            reset: reset.then_some(CENTRE),
            points: vec![CENTRE; n],
            returns: reset,
        }
    }

    /// The campaign pins the first unknown (information 10⁴): a pose that adds 100 to it
    /// gains ln(1 + 100/10001), one that adds 1 to the second ln 2; the second is chosen.
    #[test]
    fn the_next_pose_goes_where_nothing_is_determined() {
        let g0 = DMatrix::from_diagonal(&DVector::from_vec(vec![1e4, 0.0]));
        let blocks = vec![vec![
            DMatrix::from_row_slice(1, 2, &[10.0, 0.0]),
            DMatrix::from_row_slice(1, 2, &[0.0, 1.0]),
        ]];
        let p = determine(&g0, &[setup("a", false, 2)], &blocks, 1);
        assert_eq!(p.setups[0].points, vec![1]);
        assert_eq!(
            p.after().determined,
            1,
            "the second is at its tolerance, not better"
        );
        assert_eq!(p.before.determined, 1);
    }

    /// A relative setup costs its reset and its return: with two poses left only the setup
    /// without a reset fits, although the other's point would add more.
    #[test]
    fn a_reset_and_a_return_are_paid_when_a_setup_is_opened() {
        let g0 = DMatrix::zeros(1, 1);
        let blocks = vec![
            vec![DMatrix::from_row_slice(1, 1, &[10.0])],
            vec![DMatrix::from_row_slice(1, 1, &[1.0])],
        ];
        let setups = [setup("relative", true, 1), setup("self", false, 1)];
        let two = determine(&g0, &setups, &blocks, 2);
        assert_eq!(two.setups.len(), 1);
        assert_eq!(two.setups[0].setup.id, "self");
        let three = determine(&g0, &setups, &blocks, 3);
        assert_eq!(three.setups[0].setup.id, "relative");
        assert_eq!(three.setups[0].poses, 3);
        let design = three.design();
        assert_eq!(design.len(), 3, "reset, point, return: {design:?}");
        assert!(design[0].reset && !design[2].reset);
        assert_eq!(
            (design[2].x, design[2].y),
            CENTRE,
            "the return at the reset's target"
        );
    }

    /// √(λmax/λmin) of the normalised information: columns (1, 0) and (1, 1) have the
    /// normalised Gram matrix [[1, c], [c, 1]], c = 1/√2.
    #[test]
    fn condition_of_the_normalised_columns() {
        let j = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]);
        let c = 0.5f64.sqrt();
        let want = ((1.0 + c) / (1.0 - c)).sqrt();
        assert!((normalized_condition(&j.tr_mul(&j)) - want).abs() < 1e-12);
        assert!((condition_number(&normalize_columns(&j)) - want).abs() < 1e-12);
    }
}
