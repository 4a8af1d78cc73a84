//! Observability of parameters in a calibration Jacobian (thesis 3.3.3-3.3.5): condition
//! numbers, practical rank, and the sorted parameter list of QR with column pivoting, with the
//! condition number as each parameter is added (tables 4.4-4.8).

use nalgebra::DMatrix;

/// Condition number σ_max/σ_min of a matrix (∞ when rank-deficient or empty).
pub fn condition_number(m: &DMatrix<f64>) -> f64 {
    if m.ncols() == 0 || m.nrows() == 0 {
        return f64::INFINITY;
    }
    let sv = m.singular_values();
    let max = sv.max();
    let min = sv.min();
    if min > 0.0 {
        max / min
    } else {
        f64::INFINITY
    }
}

/// Columns scaled to unit Euclidean norm (eq. 3.25); zero columns stay zero.
pub fn normalize_columns(m: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = m.clone();
    for mut c in out.column_iter_mut() {
        let n = c.norm();
        if n > 0.0 {
            c /= n;
        }
    }
    out
}

/// Practical rank (eq. 3.27): number of singular values above `tau`.
pub fn practical_rank(m: &DMatrix<f64>, tau: f64) -> usize {
    m.singular_values().iter().filter(|&&s| s > tau).count()
}

/// One entry of the sorted parameter list.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ranked {
    /// Column index in the matrix given.
    pub column: usize,
    /// Condition number of the column-normalised matrix made of this and all earlier entries.
    pub condition_number: f64,
}

/// Column order of QR with column pivoting (Businger-Golub): at each step the column with the
/// largest norm orthogonal to the chosen ones. Ties (within 1e-12 relative) go to the earlier
/// column, so the ranking follows the parameter order where the data cannot tell; vanishing
/// columns (relative 1e-13) keep their order at the end. The one pivot order of the crate:
/// `rpkm analyze` and `--params auto` rank alike.
pub fn pivot_order(m: &DMatrix<f64>) -> Vec<usize> {
    let n = m.ncols();
    let mut work = m.clone();
    let mut remaining: Vec<usize> = (0..n).collect();
    let mut order = Vec::with_capacity(n);
    let scale = (0..n).map(|j| m.column(j).norm()).fold(0.0, f64::max);
    while !remaining.is_empty() {
        let mut pos = 0;
        let mut best_norm = -1.0;
        for (p, &j) in remaining.iter().enumerate() {
            let nj = work.column(j).norm();
            if nj > best_norm * (1.0 + 1e-12) {
                best_norm = nj;
                pos = p;
            }
        }
        let best = remaining.remove(pos);
        if best_norm > 1e-13 * scale {
            let q = work.column(best) / best_norm;
            for &j in &remaining {
                let proj = q.dot(&work.column(j));
                work.column_mut(j).axpy(-proj, &q, 1.0);
            }
        }
        order.push(best);
    }
    order
}

/// Columns in descending order of importance by QR with column pivoting (eq. 3.29-3.30): at
/// each step the column with the largest norm orthogonal to those already chosen. Columns
/// whose remaining norm vanishes (exact dependencies) come last with an infinite condition
/// number. `m` should carry the scaling the engineer wants the ranking in (range scaling:
/// each column is the effect of the parameter's plausible variation).
pub fn qr_pivot_order(m: &DMatrix<f64>) -> Vec<Ranked> {
    let n = m.ncols();
    let order = pivot_order(m);
    let mut ranked = Vec::with_capacity(n);
    for k in 0..n {
        let cols: Vec<usize> = order[..=k].to_vec();
        let sub = normalize_columns(&m.select_columns(cols.iter()));
        ranked.push(Ranked {
            column: order[k],
            condition_number: condition_number(&sub),
        });
    }
    ranked
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand-worked case: column 2 is the longest; once it is chosen, column 0 has nothing left
    /// orthogonal to it (it is a multiple of column 2). Columns 1 and 3 are equal copies and
    /// tie, so the earlier (1) goes first; then 0 and 3 are both dependent and keep their
    /// order at the end, with infinite condition numbers.
    #[test]
    fn ties_go_to_the_earlier_column_and_dependencies_come_last() {
        let m = DMatrix::from_row_slice(
            3,
            4,
            &[1.0, 0.0, 2.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert_eq!(pivot_order(&m), vec![2, 1, 0, 3]);
        let ranked = qr_pivot_order(&m);
        let columns: Vec<usize> = ranked.iter().map(|r| r.column).collect();
        assert_eq!(columns, vec![2, 1, 0, 3]);
        assert!((ranked[1].condition_number - 1.0).abs() < 1e-12);
        assert!(ranked[2].condition_number > 1e12);
    }
}
