//! Poses chosen for the TCP's accuracy: the greedy choice that lowers the expected held-out
//! RMS ([`super::forecast`]) most per pose spent, then an exchange within each opened setup.
//!
//! A relative setup's readings share the error of the reading its instrument was zeroed on
//! (and its reset pose's encoders): six errors per setup, with the covariance of one reading
//! ([`obs::zero_covariance`]). The planner carries them as unknowns of their own, each in
//! units of its spread (prior I), beside the geometry's: given them the rows are
//! independent, so a pose's information adds, and the geometry's covariance is the block of
//! the inverse. The calibration marginalises the same errors ([`obs::Form::Decorrelated`]);
//! the plan's figures are recomputed from its rows that way ([`AccuracyPlanner::plan`]).

use super::forecast::{posterior, TargetForecast};
use super::start::{design_rows, Start};
use super::types::{
    CandidateSetup, Determination, DeterminationPlan, PlanError, PlannedSetup, Unknowns,
};
use crate::analysis;
use crate::design::PlannedPose;
use crate::effects::Corrections;
use crate::noise::NoiseModel;
use crate::obs::{self, Form, Residual, Step};
use crate::params::{Model, Params};
use nalgebra::DMatrix;

/// Shared errors of one relative setup: its zero reading (x, y) and its reset's encoders.
const ZERO: usize = 6;
/// Rounds of the exchange pass at most.
const EXCHANGE_ROUNDS: usize = 3;

/// One pose's rows in units of their σ: on the unknowns (tolerance units) and on its setup's
/// shared errors (units of their spread).
#[derive(Clone, Debug)]
pub struct PoseRows {
    theta: DMatrix<f64>,
    zero: DMatrix<f64>,
}

/// A candidate setup's rows: each point's, and its return's where it has one.
#[derive(Clone, Debug)]
pub struct SetupRows {
    points: Vec<PoseRows>,
    back: Option<PoseRows>,
    /// Whether its rows share a zero (a reset pose).
    shares_zero: bool,
}

/// The rows of every point of `setup` (and of its return) on a machine at `p`, weighted
/// with `noise`, each pose on its own, the shared zero in its columns.
pub fn setup_rows(
    setup: &CandidateSetup,
    p: &Params,
    (model, noise): (Model, &NoiseModel),
    unknowns: &Unknowns,
) -> Result<SetupRows, PlanError> {
    let all: Vec<usize> = (0..setup.points.len()).collect();
    let mut design = setup.design(&all);
    design.extend(setup.return_pose());
    let c = analysis::nominal_campaign(&design, p, model)?;
    let corr = Corrections::default();
    let rows = obs::residuals_in(&c, p, model, Step::Direct, p, &corr, noise, Form::PerPose)?;
    let root = match setup.reset {
        Some(_) => symmetric_root(
            &obs::zero_covariance(noise, (p, model), &c.poses[0]).map_err(|error| {
                PlanError::Target {
                    x: design[0].x,
                    y: design[0].y,
                    error,
                }
            })?,
        ),
        None => DMatrix::zeros(ZERO, ZERO),
    };
    let first = usize::from(setup.reset.is_some());
    let of_pose = |k: usize| {
        let mine: Vec<&Residual> = rows.iter().filter(|r| r.pose == k).collect();
        PoseRows {
            theta: unknowns.block(&mine),
            zero: DMatrix::from_fn(mine.len(), ZERO, |r, j| {
                (0..ZERO)
                    .map(|i| mine[r].reset_gain[i] * root[(i, j)])
                    .sum::<f64>()
                    / mine[r].sigma
            }),
        }
    };
    Ok(SetupRows {
        points: (0..setup.points.len())
            .map(|k| of_pose(k + first))
            .collect(),
        back: setup
            .return_pose()
            .map(|_| of_pose(first + setup.points.len())),
        shares_zero: setup.reset.is_some(),
    })
}

/// The symmetric square root of a covariance (⪰ 0, perhaps singular).
fn symmetric_root(s: &nalgebra::SMatrix<f64, 6, 6>) -> DMatrix<f64> {
    let eig = DMatrix::from_fn(ZERO, ZERO, |i, j| 0.5 * (s[(i, j)] + s[(j, i)])).symmetric_eigen();
    let root = eig.eigenvalues.map(|v| v.max(0.0).sqrt());
    &eig.eigenvectors * DMatrix::from_diagonal(&root) * eig.eigenvectors.transpose()
}

/// A chosen point: candidate setup and point index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Pick {
    setup: usize,
    point: usize,
}

/// What the planner believes: the information over the unknowns and the shared errors of
/// every opened setup (prior I for each), and where each opened setup's errors are.
#[derive(Clone, Debug)]
struct Belief {
    m: DMatrix<f64>,
    n: usize,
    slot: Vec<Option<usize>>,
}

impl Belief {
    fn new(g0: &DMatrix<f64>, setups: usize) -> Belief {
        let n = g0.nrows();
        Belief {
            m: DMatrix::identity(n, n) + g0,
            n,
            slot: vec![None; setups],
        }
    }

    /// The covariance over everything believed.
    fn covariance(&self) -> DMatrix<f64> {
        // the information is I plus sums of outer products: positive definite but for
        // round-off, which the eigenvalues' floor at 1 (the prior's) absorbs
        let sym = (&self.m + self.m.transpose()) * 0.5;
        sym.clone().cholesky().map_or_else(
            || {
                let eig = sym.symmetric_eigen();
                let inv = eig.eigenvalues.map(|v| 1.0 / v.max(1.0));
                &eig.eigenvectors * DMatrix::from_diagonal(&inv) * eig.eigenvectors.transpose()
            },
            |c| c.inverse(),
        )
    }

    /// The unknowns' own covariance.
    fn theta_covariance(&self) -> DMatrix<f64> {
        self.covariance()
            .view((0, 0), (self.n, self.n))
            .into_owned()
    }

    /// Rows of `setup` over everything believed once it is open (its errors at the end
    /// where it is not yet).
    fn full(&self, rows: &[&PoseRows], setup: usize, shares: bool) -> DMatrix<f64> {
        let r: usize = rows.iter().map(|p| p.theta.nrows()).sum();
        let d = self.m.nrows()
            + if shares && self.slot[setup].is_none() {
                ZERO
            } else {
                0
            };
        let at = self.slot[setup].unwrap_or(self.m.nrows());
        let mut b = DMatrix::zeros(r, d);
        let mut row = 0;
        for p in rows {
            let k = p.theta.nrows();
            b.view_mut((row, 0), (k, self.n)).copy_from(&p.theta);
            if shares {
                b.view_mut((row, at), (k, ZERO)).copy_from(&p.zero);
            }
            row += k;
        }
        b
    }

    /// Adds `rows` of `setup`, opening it first where it is not open.
    fn add(&mut self, rows: &[&PoseRows], setup: usize, shares: bool) {
        let b = self.full(rows, setup, shares);
        if shares && self.slot[setup].is_none() {
            self.slot[setup] = Some(self.m.nrows());
            let d = self.m.nrows() + ZERO;
            self.m = self.m.clone().resize(d, d, 0.0);
            for k in d - ZERO..d {
                self.m[(k, k)] = 1.0;
            }
        }
        self.m += b.tr_mul(&b);
    }

    /// Removes `rows` of an open setup (the exchange's trial).
    fn remove(&mut self, rows: &[&PoseRows], setup: usize, shares: bool) {
        let b = self.full(rows, setup, shares);
        self.m -= b.tr_mul(&b);
    }
}

/// How much rows `b` (over the belief's space, extended by a setup's errors where `b` is
/// wider) lower the prediction variance, with `c` the covariance over that space:
/// tr((I + b C bᵀ)⁻¹ Wᵀ A W), W = (C bᵀ) restricted to the unknowns.
fn lowering(c: &DMatrix<f64>, b: &DMatrix<f64>, weight: &DMatrix<f64>) -> f64 {
    let n = weight.nrows();
    let w = c * b.transpose();
    let h = DMatrix::identity(b.nrows(), b.nrows()) + b * &w;
    let wt = w.view((0, 0), (n, w.ncols()));
    let q = wt.transpose() * weight * wt;
    h.cholesky().map_or(0.0, |ch| (ch.solve(&q)).trace())
}

/// The covariance `c` with a new setup's errors (prior I) appended.
fn extended(c: &DMatrix<f64>) -> DMatrix<f64> {
    let d = c.nrows() + ZERO;
    let mut e = c.clone().resize(d, d, 0.0);
    for k in d - ZERO..d {
        e[(k, k)] = 1.0;
    }
    e
}

/// Everything the greedy choice reads.
struct Ground<'a> {
    setups: &'a [CandidateSetup],
    rows: &'a [SetupRows],
    evaluation: &'a TargetForecast,
}

impl Ground<'_> {
    /// The rows a pick adds: its point's, and its setup's return where the setup opens.
    fn pick_rows(&self, pick: Pick, opening: bool) -> Vec<&PoseRows> {
        let s = &self.rows[pick.setup];
        let mut out = vec![&s.points[pick.point]];
        if opening {
            out.extend(s.back.as_ref());
        }
        out
    }

    /// The pick that lowers the prediction variance most per pose it costs within `left`
    /// poses, with its cost.
    fn best_next(&self, belief: &Belief, chosen: &[Pick], left: usize) -> Option<(Pick, usize)> {
        let c = belief.covariance();
        let mut best: Option<(Pick, usize, f64)> = None;
        for (s, setup) in self.setups.iter().enumerate() {
            let opened = chosen.iter().any(|p| p.setup == s);
            let cost = 1 + if opened { 0 } else { setup.overhead() };
            if cost > left {
                continue;
            }
            let shares = self.rows[s].shares_zero;
            let cs = if shares && belief.slot[s].is_none() {
                extended(&c)
            } else {
                c.clone()
            };
            for point in 0..self.rows[s].points.len() {
                let pick = Pick { setup: s, point };
                if chosen.contains(&pick) || self.rows[s].points[point].theta.nrows() == 0 {
                    continue;
                }
                let b = belief.full(&self.pick_rows(pick, !opened), s, shares);
                let score = lowering(&cs, &b, self.evaluation.weight()) / cost as f64;
                if score > 0.0 && best.as_ref().is_none_or(|x| score > x.2) {
                    best = Some((pick, cost, score));
                }
            }
        }
        best.map(|(p, cost, _)| (p, cost))
    }

    /// Each chosen point swapped for an unchosen point of its setup that lowers the
    /// prediction variance more, until a round changes nothing.
    fn exchange(&self, belief: &mut Belief, chosen: &mut [Pick]) {
        for _ in 0..EXCHANGE_ROUNDS {
            let mut changed = false;
            for i in 0..chosen.len() {
                let own = chosen[i];
                let shares = self.rows[own.setup].shares_zero;
                belief.remove(&self.pick_rows(own, false), own.setup, shares);
                let c = belief.covariance();
                let gain = |point: usize| {
                    let pick = Pick { point, ..own };
                    let b = belief.full(&self.pick_rows(pick, false), own.setup, shares);
                    lowering(&c, &b, self.evaluation.weight())
                };
                let keep = gain(own.point);
                let better = (0..self.rows[own.setup].points.len())
                    .filter(|&k| !chosen.iter().any(|o| o.setup == own.setup && o.point == k))
                    .map(|k| (k, gain(k)))
                    .filter(|&(_, g)| g > keep * (1.0 + 1e-9) + 1e-15)
                    .max_by(|a, b| a.1.total_cmp(&b.1));
                if let Some((k, _)) = better {
                    chosen[i].point = k;
                    changed = true;
                }
                belief.add(&self.pick_rows(chosen[i], false), own.setup, shares);
            }
            if !changed {
                break;
            }
        }
    }
}

/// The plan of `budget` poses among `setups` (their rows `rows`) that lowers the expected
/// held-out RMS of `evaluation` most from the information `g0`: greedy per pose spent (a
/// relative setup's reset and return paid when it opens), then exchanged within each setup.
pub fn choose(
    g0: &DMatrix<f64>,
    setups: &[CandidateSetup],
    rows: &[SetupRows],
    evaluation: &TargetForecast,
    budget: usize,
) -> DeterminationPlan {
    let ground = Ground {
        setups,
        rows,
        evaluation,
    };
    let mut belief = Belief::new(g0, setups.len());
    let mut chosen: Vec<Pick> = Vec::new();
    let mut used = 0;
    while let Some((pick, cost)) = ground.best_next(&belief, &chosen, budget - used) {
        let opening = !chosen.iter().any(|p| p.setup == pick.setup);
        let shares = rows[pick.setup].shares_zero;
        belief.add(&ground.pick_rows(pick, opening), pick.setup, shares);
        used += cost;
        chosen.push(pick);
    }
    ground.exchange(&mut belief, &mut chosen);
    plan_of(&ground, g0, &chosen)
}

/// The chosen points grouped by setup (in the order opened), each setup with the
/// determination and the expected held-out RMS once it and those before it are measured.
fn plan_of(ground: &Ground, g0: &DMatrix<f64>, chosen: &[Pick]) -> DeterminationPlan {
    let mut order: Vec<usize> = Vec::new();
    for p in chosen {
        if !order.contains(&p.setup) {
            order.push(p.setup);
        }
    }
    let mut belief = Belief::new(g0, ground.setups.len());
    let setups = order
        .into_iter()
        .map(|s| {
            let points: Vec<usize> = chosen
                .iter()
                .filter(|p| p.setup == s)
                .map(|p| p.point)
                .collect();
            let shares = ground.rows[s].shares_zero;
            for (k, &point) in points.iter().enumerate() {
                let rows = ground.pick_rows(Pick { setup: s, point }, k == 0);
                belief.add(&rows, s, shares);
            }
            let c = belief.theta_covariance();
            PlannedSetup {
                setup: ground.setups[s].clone(),
                poses: points.len() + ground.setups[s].overhead(),
                points,
                after: Determination::of(&information_of(&c)),
                expected_mm: Some(ground.evaluation.rms(&c)),
            }
        })
        .collect();
    DeterminationPlan {
        before: Determination::of(g0),
        setups,
    }
}

/// The information a posterior covariance `c` stands for under the tolerance prior:
/// C⁻¹ − I.
fn information_of(c: &DMatrix<f64>) -> DMatrix<f64> {
    let n = c.nrows();
    let inv = c
        .clone()
        .cholesky()
        .map_or_else(|| DMatrix::identity(n, n), |ch| ch.inverse());
    inv - DMatrix::identity(n, n)
}

/// The information of `design`'s rows on `unknowns` as the calibration weighs them (each
/// setup's shared zero marginalised), on a machine at `p`.
pub fn design_information(
    design: &[PlannedPose],
    p: &Params,
    (model, noise): (Model, &NoiseModel),
    unknowns: &Unknowns,
) -> Result<DMatrix<f64>, PlanError> {
    Ok(unknowns.information(&design_rows(design, p, model, noise)?))
}

/// What a plan for the TCP buys: the expected held-out RMS now and after it, mm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Forecast {
    pub now_mm: f64,
    pub after_mm: f64,
    /// The part of either that the held-out readings' own noise makes, mm.
    pub floor_mm: f64,
}

/// Plans for the TCP from one start: the campaign's information and every candidate
/// setup's rows computed once for every budget and every random draw.
pub struct AccuracyPlanner<'a> {
    start: &'a Start<'a>,
    unknowns: &'a Unknowns,
    setups: &'a [CandidateSetup],
    evaluation: &'a TargetForecast,
    rows: Vec<SetupRows>,
    g0: DMatrix<f64>,
}

impl<'a> AccuracyPlanner<'a> {
    /// The planner among `setups` for the TCP over `evaluation`, from `start`.
    pub fn new(
        start: &'a Start<'a>,
        unknowns: &'a Unknowns,
        setups: &'a [CandidateSetup],
        evaluation: &'a TargetForecast,
    ) -> Result<Self, PlanError> {
        let at = (start.model, start.noise);
        let rows = setups
            .iter()
            .map(|s| setup_rows(s, start.params, at, unknowns))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(AccuracyPlanner {
            g0: start.information(unknowns)?,
            start,
            unknowns,
            setups,
            evaluation,
            rows,
        })
    }

    /// The plan of `budget` poses that lowers the expected held-out RMS most, with its
    /// forecast recomputed from the plan's rows as the calibration weighs them.
    pub fn plan(&self, budget: usize) -> Result<(DeterminationPlan, Forecast), PlanError> {
        let plan = choose(&self.g0, self.setups, &self.rows, self.evaluation, budget);
        let added = self.information(&plan.design())?;
        Ok((
            plan,
            Forecast {
                now_mm: self.evaluation.rms_of_information(&self.g0),
                after_mm: self.evaluation.rms(&posterior(&(&self.g0 + added))),
                floor_mm: self.evaluation.floor_mm,
            },
        ))
    }

    /// The expected held-out RMS (mm) after `design` is measured too.
    pub fn after(&self, design: &[PlannedPose]) -> Result<f64, PlanError> {
        let added = self.information(design)?;
        Ok(self.evaluation.rms(&posterior(&(&self.g0 + added))))
    }

    /// The expected held-out RMS (mm) after `poses` poses of `setup` at random: its reset,
    /// then points drawn without repeats among its points (no return: what a user measures
    /// without a plan); the median over `draws` draws seeded from `seed`.
    pub fn random(
        &self,
        (setup, poses): (&CandidateSetup, usize),
        (draws, seed): (usize, u64),
    ) -> Result<f64, PlanError> {
        use rand::seq::SliceRandom;
        use rand::SeedableRng;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let points = poses
            .saturating_sub(usize::from(setup.reset.is_some()))
            .min(setup.points.len());
        let all: Vec<usize> = (0..setup.points.len()).collect();
        let mut rms = Vec::with_capacity(draws);
        for _ in 0..draws {
            let picked: Vec<usize> = all.choose_multiple(&mut rng, points).copied().collect();
            rms.push(self.after(&setup.design(&picked))?);
        }
        rms.sort_by(f64::total_cmp);
        Ok(rms.get(rms.len() / 2).copied().unwrap_or(f64::NAN))
    }

    fn information(&self, design: &[PlannedPose]) -> Result<DMatrix<f64>, PlanError> {
        design_information(
            design,
            self.start.params,
            (self.start.model, self.start.noise),
            self.unknowns,
        )
    }
}
