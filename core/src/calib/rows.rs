//! The weighted rows of a calibration: the problem's fixed inputs, the dependency matrix and
//! the weighted Jacobians the steps and the uncertainty share.

use super::types::{Link, Options};
use crate::campaign::Campaign;
use crate::effects::{Corrections, EffectSet};
use crate::noise::NoiseModel;
use crate::obs::{Direction, Evaluation, Form, Pieces, PoseError, Residual, Step};
use crate::params::{Model, Params, N_PARAMS};
use nalgebra::{DMatrix, DVector};
use std::collections::HashSet;
use std::sync::atomic::{AtomicUsize, Ordering};
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
        // the pieces this worker claims, one after the other; the row buffer reused
        let run = |claims: Claims| {
            let mut rows = self.take_buffer();
            let mut out = Vec::new();
            for k in claims {
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
        in_piece_order(threads, n, run).into_iter().collect()
    }
}

/// The pieces one worker claims, one at a time and in increasing order, from a counter the
/// workers share: a worker that starts late (a thread to start, a core busy with another
/// process) takes what is left instead of holding a fixed share back.
pub(super) struct Claims<'a> {
    next: &'a AtomicUsize,
    n: usize,
}

impl Iterator for Claims<'_> {
    type Item = usize;

    fn next(&mut self) -> Option<usize> {
        let k = self.next.fetch_add(1, Ordering::Relaxed);
        (k < self.n).then_some(k)
    }
}

/// `run` on `threads` scoped threads sharing the `n` pieces ([`Claims`]; each result with
/// its piece's index), the results in piece order: each piece's result is the same
/// whichever thread made it, so the whole is the same whatever the thread count. A worker
/// stops at its first failing piece; the others go on, so every piece before the first
/// failure in piece order is made, as one thread would have made them.
pub(super) fn in_piece_order<T: Send>(
    threads: usize,
    n: usize,
    run: impl Fn(Claims) -> Vec<(usize, T)> + Sync,
) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let claims = || Claims { next: &next, n };
    let mut done = if threads <= 1 {
        run(claims())
    } else {
        std::thread::scope(|scope| {
            // the calling thread claims pieces too: one thread started and joined less per
            // evaluation
            let workers: Vec<_> = (1..threads)
                .map(|_| {
                    let (run, claims) = (&run, &claims);
                    scope.spawn(move || run(claims()))
                })
                .collect();
            let mut done = run(claims());
            for w in workers {
                // a panic in a piece is a bug: it goes on in this thread
                done.extend(w.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
            }
            done
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
        Columns::factor(all_columns(rows, n_theta))
    }

    /// The R factor of a block's weighted Jacobian in all 29 + k columns
    /// ([`all_columns`]).
    pub fn factor(j: DMatrix<f64>) -> DMatrix<f64> {
        j.qr().r()
    }

    /// The pieces' R factors combined in order (each step the QR of two stacked factors).
    /// Once the factor so far is square, a piece is folded in by [`Stack::factor`]: the
    /// QR's operations on the stack's non-zero entries only, the same numbers.
    pub fn combine(pieces: Vec<DMatrix<f64>>, n_theta: usize) -> Columns {
        let cols = N_PARAMS + n_theta;
        let mut r = DMatrix::zeros(0, cols);
        for mut piece in pieces {
            if r.nrows() == cols && piece.nrows() <= cols {
                Stack::new(&mut r, &mut piece).factor();
                continue;
            }
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

/// The QR of `r` (n × n, upper triangular) stacked on `piece` (q × n, q ≤ n, zero below its
/// diagonal) as `nalgebra`'s Householder QR makes it, operation for operation, but on the
/// stack's non-zero entries only: the rows of `r` below step k's row and of `piece` below
/// its row k are zero in column k, and a reflection only negates them (when the step's
/// sign is −1) in the columns to the right. Those negations are applied when such a row
/// joins a reflection ([`Stack::step`]). Every product and sum the QR makes with a non-zero
/// entry is made, in the same order (the 8 accumulators of its dot products included),
/// so the factor is the same to the bit, at a quarter of the operations. It follows
/// `nalgebra` 0.33's QR: `folded_piece_is_the_stacked_qr_to_the_bit` says when another
/// version makes it differently.
struct Stack<'a> {
    r: &'a mut DMatrix<f64>,
    piece: &'a mut DMatrix<f64>,
    /// The product of the signs of the reflections so far: the factor of every row not yet
    /// in a reflection.
    sign: f64,
}

impl<'a> Stack<'a> {
    fn new(r: &'a mut DMatrix<f64>, piece: &'a mut DMatrix<f64>) -> Stack<'a> {
        Stack {
            r,
            piece,
            sign: 1.0,
        }
    }

    /// All n steps; `r` becomes the R factor of the stack.
    fn factor(mut self) {
        for k in 0..self.r.ncols() {
            self.step(k);
        }
    }

    /// Step k of the QR: the reflection that clears column k below the diagonal.
    fn step(&mut self, k: usize) {
        let (n, q) = (self.r.ncols(), self.piece.nrows());
        let h = q.min(k + 1);
        // where the piece's rows stand in the reflection's vector (rows k.. of the stack),
        // and how much of it the dot products' 8 accumulators take
        let at = n - k;
        let len = n + q - k;
        let dot = Dot {
            at,
            unrolled: len - len % 8,
        };
        // row k of r and of the piece join: the negations they were spared
        if self.sign < 0.0 {
            for j in k..n {
                self.r[(k, j)] = -self.r[(k, j)];
                if k < q {
                    self.piece[(k, j)] = -self.piece[(k, j)];
                }
            }
        }
        let cells = self.piece.as_mut_slice();
        let (left, right) = cells.split_at_mut((k + 1) * q);
        let xs = &mut left[k * q..k * q + h];
        // nalgebra's reflection_axis_mut
        let mut x0 = self.r[(k, k)];
        let squared = dot.of(x0, x0, xs, xs);
        let norm = squared.sqrt();
        let (modulus, sign) = if x0 >= 0.0 { (x0, 1.0) } else { (-x0, -1.0) };
        let signed_norm = sign * norm;
        let factor = (squared + modulus * norm) * 2.0;
        x0 += signed_norm;
        if factor == 0.0 {
            self.r[(k, k)] = signed_norm.abs();
            return;
        }
        let root = factor.sqrt();
        x0 /= root;
        for x in xs.iter_mut() {
            *x /= root;
        }
        let unit = dot.of(x0, x0, xs, xs).sqrt();
        x0 /= unit;
        for x in xs.iter_mut() {
            *x /= unit;
        }
        // nalgebra's reflect_with_sign, the sign making the diagonal −signed_norm
        let diagonal = -signed_norm;
        let sign = diagonal.signum();
        let m_two = sign * -2.0;
        for (j, col) in (k + 1..n).zip(right.chunks_exact_mut(q)) {
            let ys = &mut col[..h];
            let y0 = self.r[(k, j)];
            let a = (dot.of(x0, y0, xs, ys) - 0.0) * m_two;
            self.r[(k, j)] = a * x0 * 1.0 + sign * y0;
            for (y, x) in ys.iter_mut().zip(xs.iter()) {
                *y = a * *x * 1.0 + sign * *y;
            }
        }
        self.r[(k, k)] = diagonal.abs();
        self.sign *= sign;
    }
}

/// nalgebra's dot product of two vectors of a reflection (rows k.. of the stack) from their
/// non-zero entries: the first (`x0`, `y0`) and the piece's rows from index `at` on.
#[derive(Clone, Copy)]
struct Dot {
    at: usize,
    /// Entries before this index go to 8 accumulators (index mod 8), the rest one by one.
    unrolled: usize,
}

impl Dot {
    fn of(self, x0: f64, y0: f64, xs: &[f64], ys: &[f64]) -> f64 {
        let mut acc = [0.0f64; 8];
        if self.unrolled > 0 {
            acc[0] += x0 * y0;
        }
        let split = self.unrolled.saturating_sub(self.at).min(xs.len());
        // entry m goes to accumulator (at + m) mod 8: up to the first multiple of 8, then
        // whole rounds of 8 (each accumulator's terms in the same order)
        let head = ((8 - self.at % 8) % 8).min(split);
        for (m, (x, y)) in xs[..head].iter().zip(&ys[..head]).enumerate() {
            acc[(self.at + m) % 8] += x * y;
        }
        let (xr, yr) = (
            xs[head..split].chunks_exact(8),
            ys[head..split].chunks_exact(8),
        );
        let (xt, yt) = (xr.remainder(), yr.remainder());
        for (x, y) in xr.zip(yr) {
            for ((a, x), y) in acc.iter_mut().zip(x).zip(y) {
                *a += x * y;
            }
        }
        for ((a, x), y) in acc.iter_mut().zip(xt).zip(yt) {
            *a += x * y;
        }
        let mut res = 0.0;
        res += acc[0] + acc[4];
        res += acc[1] + acc[5];
        res += acc[2] + acc[6];
        res += acc[3] + acc[7];
        if self.unrolled == 0 {
            res += x0 * y0;
        }
        for (x, y) in xs[split..].iter().zip(&ys[split..]) {
            res += x * y;
        }
        res
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

/// Weighted Jacobian (m × (29 + k)) of rows in every column: the 29 parameters', then the
/// `n_theta` effect parameters'.
pub(super) fn all_columns(rows: &[Residual], n_theta: usize) -> DMatrix<f64> {
    let all: Vec<usize> = (0..n_theta).collect();
    let mut j = DMatrix::zeros(rows.len(), N_PARAMS + n_theta);
    j.columns_mut(0, N_PARAMS)
        .copy_from(&weighted_jacobian(rows));
    j.columns_mut(N_PARAMS, n_theta)
        .copy_from(&weighted_theta(rows, &all));
    j
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

    /// Numbers uniform in [−0.5, 0.5) from `seed` (xorshift64): the same matrices on every
    /// run without a random-number crate.
    fn uniform(mut x: u64) -> impl FnMut() -> f64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    /// R factors of blocks combined in order are the R factor of the whole: RᵀR = JᵀJ (the
    /// Gram matrix every selection and scaling reads), for blocks with fewer rows than
    /// columns too.
    #[test]
    fn combined_block_factors_keep_the_gram_matrix() {
        let mut next = uniform(0x9e37_79b9_7f4a_7c15_u64);
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

    /// A piece folded into a square factor ([`Stack`]) gives nalgebra's QR of the stack to
    /// the bit: pieces of fewer rows than columns and of as many, with columns that are zero
    /// in a piece (another setup's alignment angle) and a column that is zero everywhere.
    #[test]
    fn folded_piece_is_the_stacked_qr_to_the_bit() {
        let mut next = uniform(0x2545_f491_4f6c_dd1d_u64);
        let cols = N_PARAMS + 7;
        for rows in [1, 5, 9, 17, 40, cols, 300] {
            let mut block = |m: usize, zero: usize| {
                let j = DMatrix::from_fn(m, cols, |_, k| {
                    if k == N_PARAMS + zero || k == cols - 1 {
                        0.0
                    } else {
                        next() * 10f64.powi(i32::try_from(k % 5).expect("below 5") - 2)
                    }
                });
                j.qr().r()
            };
            let (first, piece) = (block(200, 1), block(rows, 3));
            let got = Columns::combine(vec![first.clone(), piece.clone()], 7).r;
            // the factor so far: the first piece's R through the stacked QR
            let first = Columns::combine(vec![first], 7).r;
            let mut both = DMatrix::zeros(first.nrows() + piece.nrows(), cols);
            both.rows_mut(0, first.nrows()).copy_from(&first);
            both.rows_mut(first.nrows(), piece.nrows())
                .copy_from(&piece);
            let want = both.qr().r();
            assert_eq!(got.shape(), want.shape());
            for (g, w) in got.iter().zip(want.iter()) {
                assert!(g.to_bits() == w.to_bits(), "{rows} rows: {g:e} vs {w:e}");
            }
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
