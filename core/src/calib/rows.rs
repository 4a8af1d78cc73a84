//! The weighted rows of a calibration: the problem's fixed inputs, the dependency matrix and
//! the weighted Jacobians the steps and the uncertainty share.

use super::{Link, Options};
use crate::campaign::Campaign;
use crate::effects::{Corrections, EffectSet};
use crate::noise::NoiseModel;
use crate::obs::{Direction, Evaluation, Form, Pieces, PoseError, Residual, Step};
use crate::params::{Model, Params, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::HashSet;
use std::sync::{Mutex, PoisonError};

/// A row's identity across evaluations: its pose and direction (what outlier elimination
/// drops).
pub(super) type Key = (usize, Direction);

/// Poses per piece of an evaluation: the unit of parallel work. Small enough that a piece's
/// rows stay in cache and two cores share a campaign evenly, large enough that the per-piece
/// sums cost nothing beside the geometry.
const PIECE_POSES: usize = 256;

/// What stays fixed through one calibration: the campaign, the model, the start parameters,
/// the noise that weights the rows and the effects bound to the campaign. Built once; every
/// evaluation of the rows goes through it.
pub(super) struct Problem<'a> {
    pub campaign: &'a Campaign,
    pub model: Model,
    pub start: Params,
    pub noise: &'a NoiseModel,
    pub effects: &'a EffectSet,
    pub opts: &'a Options,
    /// The campaign cut into pieces, once.
    pub pieces: Pieces,
    /// The row buffers of the evaluations' workers, kept from one evaluation to the next (a
    /// piece's 512 rows are 200 kB: fresh pages on every evaluation otherwise).
    buffers: Mutex<Vec<Vec<Residual>>>,
}

impl<'a> Problem<'a> {
    pub fn new(
        campaign: &'a Campaign,
        start: Params,
        effects: &'a EffectSet,
        opts: &'a Options,
    ) -> Problem<'a> {
        Problem {
            campaign,
            model: opts.model,
            start,
            noise: &opts.noise,
            effects,
            opts,
            pieces: Pieces::new(campaign, PIECE_POSES),
            buffers: Mutex::new(Vec::new()),
        }
    }

    /// The rows of `step` at parameters `p` (virtual measurements made with `p_cal`) with the
    /// effects' corrections `corr`, less the rows in `drop`.
    pub fn rows(
        &self,
        step: Step,
        p: &Params,
        p_cal: &Params,
        corr: &Corrections,
        drop: &HashSet<Key>,
    ) -> Result<Vec<Residual>, PoseError> {
        let pieces = self.map_pieces(step, p, p_cal, corr, drop, <[Residual]>::to_vec)?;
        Ok(pieces.concat())
    }

    /// `each` applied to the rows of every piece (less `drop`), on the options' threads; the
    /// results in piece order, so that sums over them do not depend on the thread count.
    /// The first failing piece's error, as a sequential evaluation would report it.
    pub fn map_pieces<T: Send>(
        &self,
        step: Step,
        p: &Params,
        p_cal: &Params,
        corr: &Corrections,
        drop: &HashSet<Key>,
        each: impl Fn(&[Residual]) -> T + Sync,
    ) -> Result<Vec<T>, PoseError> {
        let eval = Evaluation {
            campaign: self.campaign,
            p,
            model: self.model,
            step,
            p_cal,
            corr,
            noise: self.noise,
            form: Form::Decorrelated,
        };
        let n = self.pieces.len();
        // one piece after the other from `first`, every `stride`-th; the row buffer reused
        let run = |first: usize, stride: usize| {
            let mut rows = self.take_buffer();
            let mut out = Vec::new();
            for k in (first..n).step_by(stride) {
                rows.clear();
                if let Err(e) = eval.piece_into(&self.pieces, k, &mut rows) {
                    out.push((k, Err(e)));
                    break;
                }
                rows.retain(|r| !drop.contains(&(r.pose, r.direction)));
                out.push((k, Ok(each(&rows))));
            }
            self.give_buffer(rows);
            out
        };
        let threads = thread_count(self.opts.threads).min(n.max(1));
        in_piece_order(threads, run).into_iter().collect()
    }
}

/// `run(first, stride)` on `threads` scoped threads (every `stride`-th piece from `first`,
/// each result with its piece's index), the results in piece order: the same whatever the
/// thread count.
pub(super) fn in_piece_order<T: Send>(
    threads: usize,
    run: impl Fn(usize, usize) -> Vec<(usize, T)> + Sync,
) -> Vec<T> {
    let mut done = if threads <= 1 {
        run(0, 1)
    } else {
        std::thread::scope(|scope| {
            let workers: Vec<_> = (0..threads)
                .map(|t| {
                    let run = &run;
                    scope.spawn(move || run(t, threads))
                })
                .collect();
            workers
                .into_iter()
                // a panic in a piece is a bug: it goes on in this thread
                .flat_map(|w| w.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .collect()
        })
    };
    done.sort_by_key(|(k, _)| *k);
    done.into_iter().map(|(_, t)| t).collect()
}

impl Problem<'_> {
    /// A row buffer of an earlier evaluation, or a new one.
    fn take_buffer(&self) -> Vec<Residual> {
        // a poisoned lock only means another worker panicked (a bug it re-raises): the
        // buffers themselves are plain vectors, whatever state they were left in
        let mut pool = self.buffers.lock().unwrap_or_else(PoisonError::into_inner);
        pool.pop().unwrap_or_default()
    }

    /// Returns `rows` for the next evaluation.
    fn give_buffer(&self, mut rows: Vec<Residual>) {
        rows.clear();
        let mut pool = self.buffers.lock().unwrap_or_else(PoisonError::into_inner);
        pool.push(rows);
    }
}

/// `threads` resolved: 0 is every core.
pub(super) fn thread_count(threads: usize) -> usize {
    if threads == 0 {
        std::thread::available_parallelism().map_or(1, std::num::NonZero::get)
    } else {
        threads
    }
}

/// The dependency matrix D (29 × n) for the identified `ids` with `links`.
pub(super) fn dependency(ids: &[usize], links: &[Link]) -> DMatrix<f64> {
    let mut d = DMatrix::zeros(N_PARAMS, ids.len());
    for (k, &i) in ids.iter().enumerate() {
        d[(i, k)] = 1.0;
    }
    for link in links {
        for &(j, a) in &link.terms {
            if let Some(k) = ids.iter().position(|&i| i == j) {
                d[(link.param, k)] += a;
            }
        }
    }
    d
}

/// A campaign's weighted Jacobian over the 29 parameters and then every effect parameter,
/// compressed to the R factor of its QR decomposition: R has the columns' norms, angles and
/// singular values of the rows themselves (RᵀR = JᵀJ, without squaring the condition
/// number), in (29 + k)² numbers whatever the campaign's size. The selection, the scaling
/// and the effects' observability read it instead of an m × n matrix.
pub(super) struct Columns {
    r: DMatrix<f64>,
}

impl Columns {
    /// The R factor of one block of rows with `n_theta` effect parameters.
    pub fn piece(rows: &[Residual], n_theta: usize) -> DMatrix<f64> {
        let all: Vec<usize> = (0..n_theta).collect();
        let mut j = DMatrix::zeros(rows.len(), N_PARAMS + n_theta);
        j.columns_mut(0, N_PARAMS)
            .copy_from(&weighted_jacobian(rows));
        j.columns_mut(N_PARAMS, n_theta)
            .copy_from(&weighted_theta(rows, &all));
        j.qr().r()
    }

    /// The pieces' R factors combined in order (each step the QR of two stacked factors).
    pub fn combine(pieces: Vec<DMatrix<f64>>, n_theta: usize) -> Columns {
        let cols = N_PARAMS + n_theta;
        let mut r = DMatrix::zeros(0, cols);
        for piece in pieces {
            let mut both = DMatrix::zeros(r.nrows() + piece.nrows(), cols);
            both.rows_mut(0, r.nrows()).copy_from(&r);
            both.rows_mut(r.nrows(), piece.nrows()).copy_from(&piece);
            r = both.qr().r();
        }
        Columns { r }
    }

    /// Columns of `rows` (materialised rows: step 2's virtual ones).
    pub fn of(rows: &[Residual], n_theta: usize) -> Columns {
        Columns::combine(vec![Columns::piece(rows, n_theta)], n_theta)
    }

    /// The 29 geometric columns.
    pub fn geometric(&self) -> DMatrix<f64> {
        self.r.columns(0, N_PARAMS).into_owned()
    }

    /// Columns of the parameters `ids` under links (what [`reduced_jacobian`] is to rows).
    pub fn reduced(&self, ids: &[usize], links: &[Link]) -> DMatrix<f64> {
        self.r.columns(0, N_PARAMS) * dependency(ids, links)
    }

    /// Columns of the effect parameters `free`.
    pub fn theta(&self, free: &[usize]) -> DMatrix<f64> {
        DMatrix::from_fn(self.r.nrows(), free.len(), |i, k| {
            self.r[(i, N_PARAMS + free[k])]
        })
    }
}

/// Weighted residual vector of rows.
pub(super) fn weighted_values(rows: &[Residual]) -> DVector<f64> {
    DVector::from_iterator(rows.len(), rows.iter().map(|row| row.value / row.sigma))
}

/// Weighted Jacobian (m × 29) of rows.
pub(super) fn weighted_jacobian(rows: &[Residual]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), N_PARAMS, |i, k| {
        rows[i].jacobian[k] / rows[i].sigma
    })
}

/// Weighted Jacobian columns (m × k) of the effect parameters `free`. Every row of a
/// calibration with effects carries the derivative for each of them (a row without effects
/// has none, and `free` is then empty).
pub(super) fn weighted_theta(rows: &[Residual], free: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), free.len(), |i, k| {
        rows[i].d_theta[free[k]] / rows[i].sigma
    })
}

/// Weighted Jacobian columns (m × n) for parameters `ids` under links.
pub(super) fn reduced_jacobian(rows: &[Residual], ids: &[usize], links: &[Link]) -> DMatrix<f64> {
    weighted_jacobian(rows) * dependency(ids, links)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{L4, L5, XA4R};

    /// R factors of blocks combined in order are the R factor of the whole: RᵀR = JᵀJ (the
    /// Gram matrix every selection and scaling reads), for blocks with fewer rows than
    /// columns too.
    #[test]
    fn combined_block_factors_keep_the_gram_matrix() {
        let mut x = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let cols = N_PARAMS + 3;
        let j = DMatrix::from_fn(700, cols, |_, k| {
            next() * 10f64.powi(i32::try_from(k % 7).expect("below 7") - 3)
        });
        let blocks = [0..5, 5..260, 260..290, 290..700]
            .map(|r| j.rows(r.start, r.len()).into_owned().qr().r());
        let columns = Columns::combine(blocks.to_vec(), 3);
        let (gram, want) = (columns.r.tr_mul(&columns.r), j.tr_mul(&j));
        let scale = want.amax();
        assert!((gram - &want).amax() < 1e-12 * scale);
        let norms = |m: &DMatrix<f64>| (0..cols).map(|k| m.column(k).norm()).collect::<Vec<_>>();
        for (a, b) in norms(&columns.r).iter().zip(norms(&j)) {
            assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
        }
    }

    /// D maps the reduced unknowns to the 29 parameters: each identified parameter moves
    /// itself, and a linked one follows its terms (l5 = l4 + 0.5·xa4r, made up for the test).
    #[test]
    fn dependency_moves_linked_parameters_with_their_terms() {
        let links = [Link {
            param: L5,
            terms: vec![(L4, 1.0), (XA4R, 0.5)],
        }];
        let d = dependency(&[L4, XA4R], &links);
        assert_eq!(d.shape(), (N_PARAMS, 2));
        assert_eq!((d[(L4, 0)], d[(XA4R, 1)]), (1.0, 1.0));
        assert_eq!((d[(L5, 0)], d[(L5, 1)]), (1.0, 0.5));
        assert_eq!(d.iter().filter(|&&v| v != 0.0).count(), 4);
    }
}
