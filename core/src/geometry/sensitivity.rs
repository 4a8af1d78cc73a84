//! The implicit-function sensitivities of a solution to the parameters and the known variables.

use super::closure::{closure_params_with, closure_with, Frames, Trig};
use super::config::{GeometryError, ParamJacobian, Solution, Subsystem, PSI};
use super::newton::checked_lu;
use crate::params::{Model, Params, N_PARAMS};
use nalgebra::SMatrix;

/// Sensitivities of a solved configuration: to the parameters (7×29) and to the two known
/// variables (7×2). Rows of known variables are zero (parameters) or unit (knowns).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensitivity {
    pub dc_dp: ParamJacobian,
    pub dc_dk: SMatrix<f64, 7, 2>,
}

impl Sensitivity {
    /// All zero: a buffer for [`sensitivity_into`].
    pub fn zeros() -> Sensitivity {
        Sensitivity {
            dc_dp: ParamJacobian::zeros(),
            dc_dk: SMatrix::zeros(),
        }
    }
}

/// Implicit-function sensitivities of `sol` (solved for `sub`).
pub fn sensitivity(
    p: &Params,
    model: Model,
    sub: Subsystem,
    sol: &Solution,
) -> Result<Sensitivity, GeometryError> {
    let mut out = Sensitivity::zeros();
    sensitivity_into(p, model, sub, sol, &mut out)?;
    Ok(out)
}

/// [`sensitivity`] written into `out` (every entry: a buffer reused from pose to pose needs
/// no clearing), the trigonometry of the configuration once for both derivatives: a row's
/// 1.7 kB are written once where they are read instead of copied through each return.
/// `out` is left as it was where the configuration is singular.
pub fn sensitivity_into(
    p: &Params,
    model: Model,
    sub: Subsystem,
    sol: &Solution,
    out: &mut Sensitivity,
) -> Result<(), GeometryError> {
    let unknown = sub.unknown();
    let known = sub.known();
    let t = Trig::new(p, &sol.c);
    let cl = closure_with(p, model, &sol.c, &t);
    let lu = checked_lu(&cl.e_c, &unknown, sub)?;
    let inv = lu.inverse();
    let e_p = closure_params_with(p, model, &sol.c, &t);
    let du_dp = inv * e_p;
    let du_dk = inv * SMatrix::<f64, 5, 2>::from_fn(|r, k| cl.e_c[(r, known[k])]);
    // element by element: row views of column-major matrices copy through a strided
    // iterator that cost a third of this function. The known variables' rows: 0 for the
    // parameters, 1 for their own column (every entry written: `out` may hold a former pose)
    for (k, &v) in unknown.iter().enumerate() {
        for j in 0..N_PARAMS {
            out.dc_dp[(v, j)] = -du_dp[(k, j)];
        }
        for j in 0..2 {
            out.dc_dk[(v, j)] = -du_dk[(k, j)];
        }
    }
    for (k, &v) in known.iter().enumerate() {
        for j in 0..N_PARAMS {
            out.dc_dp[(v, j)] = 0.0;
        }
        for j in 0..2 {
            out.dc_dk[(v, j)] = if j == k { 1.0 } else { 0.0 };
        }
    }
    Ok(())
}

/// [`sensitivity_into`] of the configuration variables `vars` alone, with the guides'
/// `frames` of `p` given: their rows of `out`, the same numbers to the bit (each entry the
/// same products summed in the same order as the static product computes them); the other
/// rows are left as they were. A self-calibration row reads 2 of the 5 unknowns' rows: the
/// 5 × 5 × 29 product of every row becomes 2 × 5 × 29, and the frames' two `sin_cos` are the
/// caller's, once for all the poses of one machine.
pub(crate) fn sensitivity_rows_into<const N: usize>(
    p: &Params,
    model: Model,
    (sub, sol): (Subsystem, &Solution),
    frames: &Frames,
    vars: &[usize; N],
    out: &mut Sensitivity,
) -> Result<(), GeometryError> {
    let (known, unknown) = (sub.known(), sub.unknown());
    let t = Trig {
        psi: sol.c[PSI].sin_cos(),
        frames: *frames,
    };
    let cl = closure_with(p, model, &sol.c, &t);
    let lu = checked_lu(&cl.e_c, &unknown, sub)?;
    // the inverse's rows of the unknowns asked for (a known variable's: zero, replaced
    // below): each entry of their product is that of the full product, summed alike
    let at = vars.map(|v| unknown.iter().position(|&u| u == v));
    let inv = lu.inverse_from(at.iter().flatten().copied().min().unwrap_or(5));
    let chosen = SMatrix::<f64, N, 5>::from_fn(|r, m| at[r].map_or(0.0, |k| inv[(k, m)]));
    let du_dp = chosen * closure_params_with(p, model, &sol.c, &t);
    let du_dk = chosen * SMatrix::<f64, 5, 2>::from_fn(|r, k| cl.e_c[(r, known[k])]);
    for (r, &v) in vars.iter().enumerate() {
        if at[r].is_some() {
            for j in 0..N_PARAMS {
                out.dc_dp[(v, j)] = -du_dp[(r, j)];
            }
            for j in 0..2 {
                out.dc_dk[(v, j)] = -du_dk[(r, j)];
            }
        } else if let Some(k) = known.iter().position(|&u| u == v) {
            for j in 0..N_PARAMS {
                out.dc_dp[(v, j)] = 0.0;
            }
            for j in 0..2 {
                out.dc_dk[(v, j)] = if j == k { 1.0 } else { 0.0 };
            }
        }
    }
    Ok(())
}
