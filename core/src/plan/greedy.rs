//! Greedy Bayesian D-optimal choice of poses under a budget, then a Fedorov exchange within
//! each opened setup.

use super::types::{CandidateSetup, Determination, DeterminationPlan, PlannedSetup};
use nalgebra::DMatrix;

/// Rounds of the exchange pass at most (each visits every chosen pose once).
const EXCHANGE_ROUNDS: usize = 3;
/// Rounds of the condition number's exchange at most (a swap there gains less per round).
const CONDITION_ROUNDS: usize = 10;

/// A chosen point: candidate setup and point index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Chosen {
    pub setup: usize,
    pub point: usize,
}

/// ln det(I + B M⁻¹ Bᵀ): what the rows B add to ln det M (the matrix determinant lemma),
/// with `chol` M's factor. Zero for an empty block.
fn log_det_gain(chol: &nalgebra::Cholesky<f64, nalgebra::Dyn>, b: &DMatrix<f64>) -> f64 {
    if b.nrows() == 0 {
        return 0.0;
    }
    let w = chol.solve(&b.transpose());
    let s = DMatrix::identity(b.nrows(), b.nrows()) + b * w;
    s.cholesky().map_or(f64::NEG_INFINITY, |c| {
        2.0 * c.l().diagonal().map(f64::ln).sum()
    })
}

/// The Cholesky factor of a symmetric positive definite `m` (I + G is: G ⪰ 0).
fn factor(m: &DMatrix<f64>) -> nalgebra::Cholesky<f64, nalgebra::Dyn> {
    // symmetrised: sums of outer products drift apart by round-off
    let sym = (m + m.transpose()) * 0.5;
    nalgebra::Cholesky::new(sym.clone()).unwrap_or_else(|| {
        // G's round-off can make I + G lose definiteness only in a direction of size ~1e-16:
        // a ridge of that size restores it without changing any choice
        let n = sym.nrows();
        nalgebra::Cholesky::new(sym + DMatrix::identity(n, n) * 1e-9)
            .unwrap_or_else(|| nalgebra::Cholesky::new(DMatrix::identity(n, n)).expect("I"))
    })
}

/// The poses of `setups` (their points' blocks in `blocks`) that most increase ln det(I + G)
/// from the information `g0`, within `budget` poses: a relative setup's reset and return
/// poses are paid when the setup is first used. Greedy by gain per pose spent, then exchanged: each chosen
/// point is swapped for a better point of its own setup while one exists.
pub fn determine(
    g0: &DMatrix<f64>,
    setups: &[CandidateSetup],
    blocks: &[Vec<DMatrix<f64>>],
    budget: usize,
) -> DeterminationPlan {
    let n = g0.nrows();
    let mut m = DMatrix::identity(n, n) + g0;
    let mut chosen: Vec<Chosen> = Vec::new();
    let mut used = 0;
    while let Some((c, cost)) = best_next(&m, setups, blocks, &chosen, budget - used) {
        let b = &blocks[c.setup][c.point];
        m += b.tr_mul(b);
        used += cost;
        chosen.push(c);
    }
    exchange(&mut m, blocks, &mut chosen);
    plan_of(g0, setups, blocks, &chosen)
}

/// The point with the largest gain per pose it costs within `left` poses (None: nothing fits
/// or nothing adds information).
fn best_next(
    m: &DMatrix<f64>,
    setups: &[CandidateSetup],
    blocks: &[Vec<DMatrix<f64>>],
    chosen: &[Chosen],
    left: usize,
) -> Option<(Chosen, usize)> {
    let chol = factor(m);
    let mut best: Option<(Chosen, usize, f64)> = None;
    for (s, setup) in setups.iter().enumerate() {
        let opened = chosen.iter().any(|c| c.setup == s);
        let cost = 1 + if opened { 0 } else { setup.overhead() };
        if cost > left {
            continue;
        }
        for (k, b) in blocks[s].iter().enumerate() {
            let c = Chosen { setup: s, point: k };
            if b.nrows() == 0 || chosen.contains(&c) {
                continue;
            }
            let score = log_det_gain(&chol, b) / cost as f64;
            if score > 1e-12 && best.as_ref().is_none_or(|x| score > x.2) {
                best = Some((c, cost, score));
            }
        }
    }
    best.map(|(c, cost, _)| (c, cost))
}

/// Fedorov exchange within each setup: a chosen point is replaced by an unchosen point of
/// the same setup whose rows add more to ln det, until a round changes nothing.
fn exchange(m: &mut DMatrix<f64>, blocks: &[Vec<DMatrix<f64>>], chosen: &mut [Chosen]) {
    for _ in 0..EXCHANGE_ROUNDS {
        let mut changed = false;
        for i in 0..chosen.len() {
            let c = chosen[i];
            let old = &blocks[c.setup][c.point];
            let without = &*m - old.tr_mul(old);
            let chol = factor(&without);
            let keep = log_det_gain(&chol, old);
            let better = (0..blocks[c.setup].len())
                .filter(|&k| !chosen.iter().any(|o| o.setup == c.setup && o.point == k))
                .map(|k| (k, log_det_gain(&chol, &blocks[c.setup][k])))
                .filter(|&(_, gain)| gain > keep + 1e-9)
                .max_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((k, _)) = better {
                let new = &blocks[c.setup][k];
                *m = without + new.tr_mul(new);
                chosen[i].point = k;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}

/// Condition number of the column-normalised Jacobian whose information is `info`:
/// √(λmax/λmin) of D^-½ info D^-½, D its diagonal (∞ where a column is empty or dependent).
pub fn normalized_condition(info: &DMatrix<f64>) -> f64 {
    let d = info
        .diagonal()
        .map(|v| if v > 0.0 { 1.0 / v.sqrt() } else { 0.0 });
    let n = DMatrix::from_diagonal(&d) * info * DMatrix::from_diagonal(&d);
    let ev = ((&n + n.transpose()) * 0.5).symmetric_eigenvalues();
    let (lo, hi) = (ev.min(), ev.max());
    if lo > 0.0 {
        (hi / lo).sqrt()
    } else {
        f64::INFINITY
    }
}

/// [`determine`] without a campaign before it, then an exchange among the opened setups that
/// lowers the condition number of the column-normalised Jacobian (E-optimal in the scaled
/// parameters, as the thesis rates its campaigns) while a swap lowers it.
pub fn condition_exchange(
    setups: &[CandidateSetup],
    blocks: &[Vec<DMatrix<f64>>],
    budget: usize,
) -> DeterminationPlan {
    let n = blocks
        .iter()
        .flatten()
        .map(DMatrix::ncols)
        .next()
        .unwrap_or(0);
    let g0 = DMatrix::zeros(n, n);
    let d = determine(&g0, setups, blocks, budget);
    let mut chosen: Vec<Chosen> = Vec::new();
    for s in &d.setups {
        let k = setups.iter().position(|c| c.id == s.setup.id).unwrap_or(0);
        chosen.extend(s.points.iter().map(|&point| Chosen { setup: k, point }));
    }
    for _ in 0..CONDITION_ROUNDS {
        let points = point_exchange(&mut chosen, blocks);
        let whole = setup_exchange(&mut chosen, blocks);
        if !(points || whole) {
            break;
        }
    }
    plan_of(&g0, setups, blocks, &chosen)
}

/// The information of the chosen points.
fn info_of(chosen: &[Chosen], blocks: &[Vec<DMatrix<f64>>]) -> DMatrix<f64> {
    let n = blocks
        .iter()
        .flatten()
        .map(DMatrix::ncols)
        .next()
        .unwrap_or(0);
    let mut info = DMatrix::zeros(n, n);
    for c in chosen {
        info += blocks[c.setup][c.point].tr_mul(&blocks[c.setup][c.point]);
    }
    info
}

/// One round of single-point swaps that lower the condition number; whether one was made.
fn point_exchange(chosen: &mut [Chosen], blocks: &[Vec<DMatrix<f64>>]) -> bool {
    let mut info = info_of(chosen, blocks);
    let mut changed = false;
    for i in 0..chosen.len() {
        let c = chosen[i];
        let old = &blocks[c.setup][c.point];
        let without = &info - old.tr_mul(old);
        let now = normalized_condition(&info);
        let better = swaps(chosen, i, blocks)
            .map(|to| {
                let b = &blocks[to.setup][to.point];
                (to, normalized_condition(&(&without + b.tr_mul(b))))
            })
            .filter(|&(_, cond)| cond < now * (1.0 - 1e-9))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((to, _)) = better {
            let b = &blocks[to.setup][to.point];
            info = without + b.tr_mul(b);
            chosen[i] = to;
            changed = true;
        }
    }
    changed
}

/// One round of whole-setup swaps: each opened setup against every unopened one with as
/// many points, chosen one by one for the condition number; the best swap that lowers it is
/// made. The cost stays (one reset and return for one, as many points). Whether one was made.
fn setup_exchange(chosen: &mut Vec<Chosen>, blocks: &[Vec<DMatrix<f64>>]) -> bool {
    let mut opened: Vec<usize> = chosen.iter().map(|c| c.setup).collect();
    opened.sort_unstable();
    opened.dedup();
    let mut changed = false;
    for &s in &opened {
        let k = chosen.iter().filter(|c| c.setup == s).count();
        let rest: Vec<Chosen> = chosen.iter().copied().filter(|c| c.setup != s).collect();
        let base = info_of(&rest, blocks);
        let now = normalized_condition(&info_of(chosen, blocks));
        let taken = |t: usize| chosen.iter().any(|c| c.setup == t);
        let best = (0..blocks.len())
            .filter(|&t| !taken(t) && blocks[t].len() >= k)
            .map(|t| fill_setup(&base, t, k, blocks))
            .filter(|(_, cond)| *cond < now * (1.0 - 1e-9))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((points, _)) = best {
            *chosen = rest;
            chosen.extend(points);
            changed = true;
        }
    }
    changed
}

/// `k` points of setup `t` added one by one to `base`, each the one that lowers the
/// condition number most; with the condition number at the end.
fn fill_setup(
    base: &DMatrix<f64>,
    t: usize,
    k: usize,
    blocks: &[Vec<DMatrix<f64>>],
) -> (Vec<Chosen>, f64) {
    let mut info = base.clone();
    let mut points: Vec<Chosen> = Vec::with_capacity(k);
    for _ in 0..k {
        let next = (0..blocks[t].len())
            .filter(|&p| blocks[t][p].nrows() > 0 && !points.iter().any(|c| c.point == p))
            .map(|p| {
                let b = &blocks[t][p];
                (p, normalized_condition(&(&info + b.tr_mul(b))))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1));
        let Some((p, _)) = next else { break };
        info += blocks[t][p].tr_mul(&blocks[t][p]);
        points.push(Chosen { setup: t, point: p });
    }
    if points.len() < k {
        return (points, f64::INFINITY);
    }
    (points, normalized_condition(&info))
}

/// Where chosen point `i` may move without changing what the plan costs: to an unchosen
/// point of a setup already opened, its own setup left with a point (else its reset would
/// be paid for nothing).
fn swaps<'a>(
    chosen: &'a [Chosen],
    i: usize,
    blocks: &'a [Vec<DMatrix<f64>>],
) -> impl Iterator<Item = Chosen> + 'a {
    let own = chosen[i].setup;
    let alone = chosen.iter().filter(|c| c.setup == own).count() == 1;
    let mut opened: Vec<usize> = chosen.iter().map(|c| c.setup).collect();
    opened.sort_unstable();
    opened.dedup();
    opened
        .into_iter()
        .filter(move |&s| !alone || s == own)
        .flat_map(move |s| (0..blocks[s].len()).map(move |point| Chosen { setup: s, point }))
        .filter(move |c| blocks[c.setup][c.point].nrows() > 0 && !chosen.contains(c))
}

/// The chosen points grouped by setup (in the order the setups were opened), each setup with
/// the determination once it and those before it are measured.
fn plan_of(
    g0: &DMatrix<f64>,
    setups: &[CandidateSetup],
    blocks: &[Vec<DMatrix<f64>>],
    chosen: &[Chosen],
) -> DeterminationPlan {
    let mut order: Vec<usize> = Vec::new();
    for c in chosen {
        if !order.contains(&c.setup) {
            order.push(c.setup);
        }
    }
    let mut g = g0.clone();
    let planned = order
        .into_iter()
        .map(|s| {
            let points: Vec<usize> = chosen
                .iter()
                .filter(|c| c.setup == s)
                .map(|c| c.point)
                .collect();
            for &k in &points {
                g += blocks[s][k].tr_mul(&blocks[s][k]);
            }
            PlannedSetup {
                setup: setups[s].clone(),
                poses: points.len() + setups[s].overhead(),
                points,
                after: Determination::of(&g),
                expected_mm: None,
            }
        })
        .collect();
    DeterminationPlan {
        before: Determination::of(g0),
        setups: planned,
    }
}
