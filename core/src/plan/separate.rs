//! Separating two explanations that tie (T-optimal discrimination): a lost motion of one
//! carrier (`dir_qN`: the carrier lags its encoder by a constant against its last move) or a
//! geometric parameter. Each hypothesis predicts a signature on the rows (in units of their
//! σ); the geometry absorbs what it can of either (under its tolerance prior); what is left
//! of hypothesis A that no size of B reproduces is how far the data can tell A from B, in σ.
//! Both ways are asked (A true, B fitted; B true, A fitted) and the smaller is the
//! separation. Poses are chosen one after the other: a lost motion's sign is the direction of
//! the carrier's last move, so the order of the poses is part of the plan.

use super::types::{CandidateSetup, PlanError, Unknowns};
use crate::analysis;
use crate::campaign::motion::next_direction;
use crate::campaign::Campaign;
use crate::design::PlannedPose;
use crate::effects::Corrections;
use crate::noise::NoiseModel;
use crate::obs::{self, Residual, Step};
use crate::params::{self, Model, Params, NAMES};
use nalgebra::{DMatrix, DVector};
use std::fmt;
use std::str::FromStr;

/// Step of the finite difference of a row against an encoder reading, mm (the rows are
/// smooth in q on the scale of metres: the difference is exact to ~1e-9 relative).
const DQ: f64 = 1e-4;

/// An explanation of a residual.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hypothesis {
    /// Lost motion of carrier N (0-based): carrier minus encoder = −b · dir_qN.
    LostMotion(usize),
    /// A geometric parameter off its value.
    Parameter(usize),
}

impl FromStr for Hypothesis {
    type Err = PlanError;
    fn from_str(s: &str) -> Result<Self, PlanError> {
        let t = s.trim();
        if let Some(n) = t.strip_prefix("dir_q") {
            return match n.parse::<usize>() {
                Ok(k @ 1..=4) => Ok(Hypothesis::LostMotion(k - 1)),
                _ => Err(PlanError::UnknownHypothesis(t.to_owned())),
            };
        }
        params::index_of(t)
            .map(Hypothesis::Parameter)
            .ok_or_else(|| PlanError::UnknownHypothesis(t.to_owned()))
    }
}

impl fmt::Display for Hypothesis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Hypothesis::LostMotion(k) => write!(f, "dir_q{}", k + 1),
            Hypothesis::Parameter(i) => f.write_str(NAMES[*i]),
        }
    }
}

impl Hypothesis {
    /// The size it is judged at: `lost_motion_mm` for a lost motion, the tolerance for a
    /// parameter.
    fn magnitude(self, lost_motion_mm: f64, tolerance: &dyn Fn(usize) -> f64) -> f64 {
        match self {
            Hypothesis::LostMotion(_) => lost_motion_mm,
            Hypothesis::Parameter(i) => tolerance(i),
        }
    }
}

/// Two hypotheses and the sizes they are judged at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    pub a: Hypothesis,
    pub b: Hypothesis,
    /// Size of each (mm or rad).
    pub size: [f64; 2],
}

impl Pair {
    /// `a` against `b`, a lost motion judged at `lost_motion_mm`, a parameter at `tolerance`.
    pub fn new(
        a: Hypothesis,
        b: Hypothesis,
        lost_motion_mm: f64,
        tolerance: &dyn Fn(usize) -> f64,
    ) -> Result<Pair, PlanError> {
        if a == b {
            return Err(PlanError::SameHypothesis(a.to_string()));
        }
        Ok(Pair {
            a,
            b,
            size: [
                a.magnitude(lost_motion_mm, tolerance),
                b.magnitude(lost_motion_mm, tolerance),
            ],
        })
    }

    /// The unknowns less the pair's own parameters (they compete to explain; the geometry
    /// absorbs the rest).
    pub fn others(&self, unknowns: &Unknowns) -> Unknowns {
        let own = |i: usize| [self.a, self.b].contains(&Hypothesis::Parameter(i));
        let keep: Vec<usize> = (0..unknowns.len())
            .filter(|&k| !own(unknowns.ids[k]))
            .collect();
        Unknowns {
            ids: keep.iter().map(|&k| unknowns.ids[k]).collect(),
            tolerance: keep.iter().map(|&k| unknowns.tolerance[k]).collect(),
        }
    }
}

/// How far the data tell two hypotheses apart, in σ of the measurements.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Separation {
    /// A true at its size, B fitted (with the geometry): the residual left, in σ.
    pub a_from_b: f64,
    /// B true at its size, A fitted.
    pub b_from_a: f64,
}

impl Separation {
    /// The smaller of the two: what the data guarantee.
    pub fn sigma(&self) -> f64 {
        self.a_from_b.min(self.b_from_a)
    }
}

/// The sums the separation needs: the geometry's information and its products with the two
/// signatures.
#[derive(Clone, Debug)]
struct Sums {
    jtj: DMatrix<f64>,
    jt: [DVector<f64>; 2],
    /// s_a·s_a, s_b·s_b, s_a·s_b.
    ss: [f64; 3],
}

impl Sums {
    fn new(n: usize) -> Sums {
        Sums {
            jtj: DMatrix::zeros(n, n),
            jt: [DVector::zeros(n), DVector::zeros(n)],
            ss: [0.0; 3],
        }
    }

    fn add(&mut self, j: &DMatrix<f64>, s: &[DVector<f64>; 2]) {
        self.jtj += j.tr_mul(j);
        self.jt[0] += j.tr_mul(&s[0]);
        self.jt[1] += j.tr_mul(&s[1]);
        self.ss[0] += s[0].norm_squared();
        self.ss[1] += s[1].norm_squared();
        self.ss[2] += s[0].dot(&s[1]);
    }

    fn separation(&self) -> Separation {
        let n = self.jtj.nrows();
        let m = DMatrix::identity(n, n) + &self.jtj;
        let Some(chol) = m.cholesky() else {
            return Separation {
                a_from_b: 0.0,
                b_from_a: 0.0,
            };
        };
        let x = [chol.solve(&self.jt[0]), chol.solve(&self.jt[1])];
        // the signatures' products after the geometry has absorbed what it can
        let paa = (self.ss[0] - self.jt[0].dot(&x[0])).max(0.0);
        let pbb = (self.ss[1] - self.jt[1].dot(&x[1])).max(0.0);
        let pab = self.ss[2] - self.jt[0].dot(&x[1]);
        let left = |p: f64, q: f64| {
            if q > 0.0 {
                (p - pab * pab / q).max(0.0).sqrt()
            } else {
                p.sqrt()
            }
        };
        Separation {
            a_from_b: left(paa, pbb),
            b_from_a: left(pbb, paa),
        }
    }
}

/// One pose's rows: the geometry's block, and per hypothesis its signature's factor (times
/// the direction of the carrier's last move for a lost motion), in σ.
#[derive(Clone, Debug)]
struct PoseRows {
    j: DMatrix<f64>,
    g: [DVector<f64>; 2],
    q: [f64; 4],
}

impl PoseRows {
    /// The two signatures at carrier directions `dir`.
    fn signatures(&self, pair: &Pair, dir: &[f64; 4]) -> [DVector<f64>; 2] {
        let one = |h: Hypothesis, g: &DVector<f64>, size: f64| match h {
            Hypothesis::LostMotion(k) => g * (dir[k] * size),
            Hypothesis::Parameter(_) => g * size,
        };
        [
            one(pair.a, &self.g[0], pair.size[0]),
            one(pair.b, &self.g[1], pair.size[1]),
        ]
    }
}

/// The rows of campaign `c` at `p` grouped by pose, with the hypotheses' factors: a lost
/// motion's by a finite difference of every non-reset pose's encoder reading, a parameter's
/// its Jacobian column.
fn pose_rows(
    c: &Campaign,
    p: &Params,
    (model, noise): (Model, &NoiseModel),
    unknowns: &Unknowns,
    pair: &Pair,
) -> Result<Vec<PoseRows>, PlanError> {
    let rows = |c: &Campaign| {
        obs::residuals_with(c, p, model, Step::Direct, p, &Corrections::default(), noise)
    };
    let base = rows(c)?;
    let factor = |h: Hypothesis| -> Result<Vec<f64>, PlanError> {
        Ok(match h {
            Hypothesis::LostMotion(k) => {
                let mut moved = c.clone();
                for pose in moved.poses.iter_mut().filter(|q| !q.reset) {
                    pose.q[k] += DQ;
                }
                let shifted = rows(&moved)?;
                base.iter()
                    .zip(&shifted)
                    .map(|(r0, r1)| (r1.value - r0.value) / DQ / r0.sigma)
                    .collect()
            }
            Hypothesis::Parameter(i) => base.iter().map(|r| r.jacobian[i] / r.sigma).collect(),
        })
    };
    let g = [factor(pair.a)?, factor(pair.b)?];
    Ok((0..c.poses.len())
        .map(|k| {
            let mine: Vec<usize> = (0..base.len()).filter(|&r| base[r].pose == k).collect();
            let refs: Vec<&Residual> = mine.iter().map(|&r| &base[r]).collect();
            let pick =
                |v: &Vec<f64>| DVector::from_iterator(mine.len(), mine.iter().map(|&r| v[r]));
            PoseRows {
                j: unknowns.block(&refs),
                g: [pick(&g[0]), pick(&g[1])],
                q: c.poses[k].q,
            }
        })
        .collect())
}

/// How far campaign `c` (at parameters `p`, weighted by `noise`) tells the pair apart, the
/// geometry in `unknowns` free under its tolerance.
pub fn separation_of(
    c: &Campaign,
    p: &Params,
    (model, noise): (Model, &NoiseModel),
    unknowns: &Unknowns,
    pair: &Pair,
) -> Result<Separation, PlanError> {
    let others = pair.others(unknowns);
    let rows = pose_rows(c, p, (model, noise), &others, pair)?;
    let mut sums = Sums::new(others.len());
    let mut dir = [1.0; 4];
    for (k, r) in rows.iter().enumerate() {
        if k > 0 {
            dir = next_direction(dir, &rows[k - 1].q, &r.q);
        }
        sums.add(&r.j, &r.signatures(pair, &dir));
    }
    Ok(sums.separation())
}

/// A plan that separates two hypotheses: the poses in measuring order, one setup, and the
/// separation expected after each.
#[derive(Clone, Debug, PartialEq)]
pub struct SeparationPlan {
    pub poses: Vec<PlannedPose>,
    pub after_each: Vec<Separation>,
}

impl SeparationPlan {
    pub fn after(&self) -> Option<Separation> {
        self.after_each.last().copied()
    }
}

/// `budget` poses of `setup` (its reset first where it has one, then its points, a point
/// visited again from another side where that helps, and its return to the reset pose where
/// its instrument was zeroed on a reading), chosen one after the other to separate the pair
/// most: at each step the point whose move and rows raise the separation most.
pub fn separate(
    setup: &CandidateSetup,
    p: &Params,
    (model, noise): (Model, &NoiseModel),
    unknowns: &Unknowns,
    pair: &Pair,
    budget: usize,
) -> Result<SeparationPlan, PlanError> {
    let others = pair.others(unknowns);
    let all: Vec<usize> = (0..setup.points.len()).collect();
    let mut design = setup.design(&all);
    design.extend(setup.return_pose());
    let c = analysis::nominal_campaign(&design, p, model)?;
    let rows = pose_rows(&c, p, (model, noise), &others, pair)?;
    let first = usize::from(setup.reset.is_some());
    let points = first..first + setup.points.len();
    let back = setup.return_pose().map(|_| points.end);
    let room = budget.saturating_sub(usize::from(back.is_some()));
    let mut sums = Sums::new(others.len());
    let mut dir = [1.0; 4];
    // the reset first where there is one, else the first point
    let mut at = 0;
    let mut order = vec![at];
    let mut after_each = Vec::new();
    sums.add(&rows[at].j, &rows[at].signatures(pair, &dir));
    after_each.push(sums.separation());
    while order.len() < room {
        let step = points
            .clone()
            .filter(|&k| k != at)
            .map(|k| {
                let d = next_direction(dir, &rows[at].q, &rows[k].q);
                let mut trial = sums.clone();
                trial.add(&rows[k].j, &rows[k].signatures(pair, &d));
                let sep = trial.separation();
                (k, d, trial, sep)
            })
            .max_by(|x, y| x.3.sigma().total_cmp(&y.3.sigma()));
        let Some((k, d, trial, sep)) = step else {
            break;
        };
        after_each.push(sep);
        (sums, dir, at) = (trial, d, k);
        order.push(k);
    }
    if let Some(k) = back.filter(|_| order.len() < budget) {
        let d = next_direction(dir, &rows[at].q, &rows[k].q);
        sums.add(&rows[k].j, &rows[k].signatures(pair, &d));
        after_each.push(sums.separation());
        order.push(k);
    }
    Ok(SeparationPlan {
        poses: order.iter().map(|&k| design[k].clone()).collect(),
        after_each,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sums(j: &DMatrix<f64>, a: &[f64], b: &[f64]) -> Sums {
        let mut s = Sums::new(j.ncols());
        s.add(j, &[DVector::from_row_slice(a), DVector::from_row_slice(b)]);
        s
    }

    /// Without geometry: one signature (3, 4) against (1, 0) leaves its part across the
    /// other, 4 σ; the other against it, 1 · sin of the angle, 4/5 σ. Identical signatures
    /// tie (0), whatever their size.
    #[test]
    fn what_no_size_of_the_other_reproduces() {
        let none = DMatrix::zeros(2, 0);
        let s = sums(&none, &[3.0, 4.0], &[1.0, 0.0]).separation();
        assert!((s.a_from_b - 4.0).abs() < 1e-12);
        assert!((s.b_from_a - 0.8).abs() < 1e-12);
        assert!((s.sigma() - 0.8).abs() < 1e-12);
        let tie = sums(&none, &[1.0, 2.0], &[2.0, 4.0]).separation();
        assert!(tie.sigma() < 1e-7);
    }

    /// A geometric column equal to the first signature absorbs it under a weak prior (its
    /// size 100 tolerances): what is left of it is 1/√(1 + 100²) of it.
    #[test]
    fn the_geometry_absorbs_what_it_can() {
        let j = DMatrix::from_row_slice(2, 1, &[100.0, 0.0]);
        let s = sums(&j, &[1.0, 0.0], &[0.0, 1.0]).separation();
        assert!((s.a_from_b - (1.0 / (1.0 + 1e4f64)).sqrt()).abs() < 1e-9);
        assert!((s.b_from_a - 1.0).abs() < 1e-12);
    }

    #[test]
    fn hypotheses_by_name() {
        assert_eq!(
            "dir_q4".parse::<Hypothesis>().ok(),
            Some(Hypothesis::LostMotion(3))
        );
        assert_eq!(
            "l3".parse::<Hypothesis>().ok(),
            Some(Hypothesis::Parameter(params::L3))
        );
        assert!("dir_q5".parse::<Hypothesis>().is_err());
        assert_eq!(Hypothesis::LostMotion(1).to_string(), "dir_q2");
    }
}
