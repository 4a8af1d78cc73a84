//! Newton's polish of a start and the 5 x 5 LU with its conditioning check.

use super::closure::closure;
use super::config::{
    Config, GeometryError, Solution, Subsystem, MAX_ITER, SINGULAR_RATIO, TOL_MM2,
};
use crate::params::{Model, Params};
use nalgebra::SMatrix;

/// Solve the model's five equations for the five unknowns of `sub`, from `start`.
pub(super) fn newton(
    p: &Params,
    model: Model,
    sub: Subsystem,
    mut c: Config,
) -> Result<Solution, GeometryError> {
    let unknown = sub.unknown();
    for it in 0..=MAX_ITER {
        let cl = closure(p, model, &c);
        let residual = cl.e.amax();
        if !residual.is_finite() {
            return Err(GeometryError::NonFinite);
        }
        let e_u = select_columns(&cl.e_c, &unknown);
        let lu = Lu5::new(e_u);
        check_conditioning(&e_u, lu.map(|l| l.det), sub)?;
        if residual < TOL_MM2 {
            return Ok(Solution {
                c,
                iterations: it,
                residual,
            });
        }
        if it == MAX_ITER {
            return Err(GeometryError::NotConverged {
                what: "newton",
                iterations: it,
                residual,
            });
        }
        let step = lu
            .ok_or(GeometryError::Singular {
                subsystem: sub,
                ratio: 0.0,
            })?
            .solve(&SMatrix::<f64, 5, 1>::from(cl.e));
        for (k, &v) in unknown.iter().enumerate() {
            c[v] -= step[k];
        }
    }
    unreachable!("loop returns on its last iteration")
}

pub(super) fn select_columns(m: &SMatrix<f64, 5, 7>, cols: &[usize; 5]) -> SMatrix<f64, 5, 5> {
    SMatrix::<f64, 5, 5>::from_fn(|r, k| m[(r, cols[k])])
}

/// Singularity test free of the units of rows and columns: with every column scaled to unit
/// norm, |det| / Π ‖row‖ (1 for orthogonal rows, 0 when singular). `det` is the determinant
/// of `e_u` itself (its LU's; None when a pivot vanished): scaling the columns divides it by
/// their norms.
pub(super) fn conditioning_ratio(e_u: &SMatrix<f64, 5, 5>, det: Option<f64>) -> f64 {
    let mut m = *e_u;
    let mut scale = 1.0;
    for mut col in m.column_iter_mut() {
        let n = col.norm();
        if n > 0.0 {
            col /= n;
            scale *= n;
        }
    }
    let norms: f64 = (0..5).map(|r| m.row(r).norm()).product();
    det.map_or(0.0, |d| d.abs() / scale) / norms
}

/// Refuses `e_u` (the unknowns' columns of ∂e/∂c, determinant `det`) where its
/// [`conditioning_ratio`] is at or below [`SINGULAR_RATIO`].
fn check_conditioning(
    e_u: &SMatrix<f64, 5, 5>,
    det: Option<f64>,
    sub: Subsystem,
) -> Result<(), GeometryError> {
    let ratio = conditioning_ratio(e_u, det);
    if !(ratio > SINGULAR_RATIO) {
        return Err(GeometryError::Singular {
            subsystem: sub,
            ratio,
        });
    }
    Ok(())
}

/// The LU of the unknowns' columns of ∂e/∂c at a solution, refused where they are singular
/// or ill-conditioned ([`check_conditioning`]): what the sensitivities are solved with.
pub(super) fn checked_lu(
    e_c: &SMatrix<f64, 5, 7>,
    unknown: &[usize; 5],
    sub: Subsystem,
) -> Result<Lu5, GeometryError> {
    let e_u = select_columns(e_c, unknown);
    let lu = Lu5::new(e_u);
    check_conditioning(&e_u, lu.map(|l| l.det), sub)?;
    lu.ok_or(GeometryError::Singular {
        subsystem: sub,
        ratio: 0.0,
    })
}

/// A 5 × 5 LU factorisation with partial pivoting, on the stack: nalgebra's general LU and
/// its column-by-column triangular solves cost several times more at this size, and every
/// Newton step and every row's sensitivities (29 + 2 right-hand sides) go through one.
#[derive(Clone, Copy, Debug)]
pub(super) struct Lu5 {
    /// L below the diagonal (unit diagonal implied), U on and above it.
    pub(super) lu: SMatrix<f64, 5, 5>,
    /// Row k of the factors is row perm[k] of the matrix.
    perm: [usize; 5],
    /// 1 / U's diagonal: the solves multiply instead of dividing.
    inv_diag: [f64; 5],
    pub(super) det: f64,
}

impl Lu5 {
    /// None when a pivot is exactly zero (the determinant is then 0).
    pub(super) fn new(mut m: SMatrix<f64, 5, 5>) -> Option<Lu5> {
        let mut perm = [0, 1, 2, 3, 4];
        let mut det = 1.0;
        for k in 0..5 {
            let mut pivot = k;
            for r in k + 1..5 {
                if m[(r, k)].abs() > m[(pivot, k)].abs() {
                    pivot = r;
                }
            }
            if m[(pivot, k)] == 0.0 {
                return None;
            }
            if pivot != k {
                m.swap_rows(k, pivot);
                perm.swap(k, pivot);
                det = -det;
            }
            let d = m[(k, k)];
            det *= d;
            for r in k + 1..5 {
                let f = m[(r, k)] / d;
                m[(r, k)] = f;
                for c in k + 1..5 {
                    m[(r, c)] -= f * m[(k, c)];
                }
            }
        }
        let inv_diag = std::array::from_fn(|k| 1.0 / m[(k, k)]);
        Some(Lu5 {
            lu: m,
            perm,
            inv_diag,
            det,
        })
    }

    /// A⁻¹: five solves, after which many right-hand sides cost one static product (the
    /// sensitivities' 31).
    pub(super) fn inverse(&self) -> SMatrix<f64, 5, 5> {
        self.solve(&SMatrix::<f64, 5, 5>::identity())
    }

    /// The rows `first`.. of A⁻¹ (the others zero): the same numbers as those rows of
    /// [`Lu5::inverse`] (the same solves, the back substitution stopped at row `first`,
    /// since it runs from the last row up).
    pub(super) fn inverse_from(&self, first: usize) -> SMatrix<f64, 5, 5> {
        let mut x = SMatrix::<f64, 5, 5>::zeros();
        for c in 0..5 {
            let mut v = self.perm.map(|r| if r == c { 1.0 } else { 0.0 });
            for k in 0..5 {
                for j in 0..k {
                    v[k] -= self.lu[(k, j)] * v[j];
                }
            }
            for k in (first..5).rev() {
                for j in k + 1..5 {
                    v[k] -= self.lu[(k, j)] * v[j];
                }
                v[k] *= self.inv_diag[k];
                x[(k, c)] = v[k];
            }
        }
        x
    }

    /// X with A X = B, column by column.
    pub(super) fn solve<const N: usize>(&self, b: &SMatrix<f64, 5, N>) -> SMatrix<f64, 5, N> {
        let mut x = SMatrix::<f64, 5, N>::zeros();
        for c in 0..N {
            let mut v = [0.0; 5];
            for k in 0..5 {
                v[k] = b[(self.perm[k], c)];
            }
            for k in 0..5 {
                for j in 0..k {
                    v[k] -= self.lu[(k, j)] * v[j];
                }
            }
            for k in (0..5).rev() {
                for j in k + 1..5 {
                    v[k] -= self.lu[(k, j)] * v[j];
                }
                v[k] *= self.inv_diag[k];
            }
            for k in 0..5 {
                x[(k, c)] = v[k];
            }
        }
        x
    }
}

/// Determinant of a 5 × 5 matrix (0 when singular to the last bit).
#[cfg(test)]
pub(super) fn det5(m: SMatrix<f64, 5, 5>) -> f64 {
    Lu5::new(m).map_or(0.0, |lu| lu.det)
}
