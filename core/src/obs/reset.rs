//! What a setup's reset pose shares with all its rows: the covariance, marginalised out of the
//! rows.

use super::row::Residual;
use crate::campaign::{Instrument, MeasuredPose};
use crate::geometry::{self, GeometryError};
use crate::noise::{NoiseModel, XyInstrument};
use crate::params::Row;
use crate::params::{Model, Params};
use nalgebra::Vector2;

/// Covariance of the errors a setup's reset pose shares with all its rows, in the order of
/// [`ResetGain`]: the reading the instrument was zeroed on (at the reset pose; none for a
/// ball-bar, whose pivot is where the machine stood) and the reset pose's four encoders.
/// The reading's at the calibration's fixed `p_cal`, so that the rows' combinations stay put
/// while the parameters move.
pub fn zero_covariance(
    noise: &NoiseModel,
    (p_cal, model): (&Params, Model),
    reset: &MeasuredPose,
) -> Result<nalgebra::SMatrix<f64, 6, 6>, GeometryError> {
    let mut cov = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    for k in 2..6 {
        cov[(k, k)] = noise.encoder_mm.powi(2);
    }
    let reading = match (reset.instrument, XyInstrument::of(reset.instrument)) {
        (_, Some(xy)) => {
            let sol = geometry::fgm(p_cal, model, reset.q[0], reset.q[3])?;
            noise.xy_covariance(xy, Vector2::new(sol.x(), sol.y()))
        }
        (Instrument::LiX | Instrument::LiY | Instrument::LiPsi, None) => {
            let sigma = noise.scalar_sigma(reset.instrument).unwrap_or(0.0);
            nalgebra::Matrix2::new(sigma * sigma, 0.0, 0.0, 0.0)
        }
        _ => nalgebra::Matrix2::zeros(),
    };
    cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&reading);
    Ok(cov)
}

/// The rows of one relative setup made independent again. The setup was zeroed on a
/// reading as noisy as any other, so every row carries that reading's error e (covariance
/// `cov`) with its own gain g_i: with z = r/σ, cov(z) = I + H S Hᵀ (row i of H is g_iᵀ/σ_i,
/// S = `cov`), an offset per setup with a prior of one reading's noise, marginalised. Each
/// row becomes its row of cov(z)^(−1/2) z (value, parameters' and effects' derivatives
/// alike): with H S Hᵀ = Σ λ_k q_k q_kᵀ (rank six at most), z − Σ (1 − 1/√(1 + λ_k)) q_k
/// q_kᵀ z. Each row keeps its σ and its variance parts: the shared errors are the same
/// instruments' noise as the row's own (the reading's and the encoders'), so the noise
/// rounds estimate the level of one reading.
pub(super) fn share_reset(rows: &mut [Residual], cov: &nalgebra::SMatrix<f64, 6, 6>) {
    if rows.iter().any(|r| !(r.sigma > 0.0)) {
        return;
    }
    let eig = cov.symmetric_eigen();
    let root = eig.eigenvectors
        * nalgebra::SMatrix::<f64, 6, 6>::from_diagonal(
            &eig.eigenvalues.map(|v| v.max(0.0).sqrt()),
        )
        * eig.eigenvectors.transpose();
    let k: Vec<nalgebra::SMatrix<f64, 1, 6>> = rows
        .iter()
        .map(|r| r.reset_gain.transpose() / r.sigma * root)
        .collect();
    let m = k
        .iter()
        .fold(nalgebra::SMatrix::<f64, 6, 6>::zeros(), |m, ki| {
            m + ki.transpose() * ki
        });
    let modes = m.symmetric_eigen();
    for c in 0..6 {
        let lambda = modes.eigenvalues[c];
        if !(lambda > 1e-12) {
            continue;
        }
        let v = modes.eigenvectors.column(c);
        let q: Vec<f64> = k.iter().map(|ki| (ki * v)[0] / lambda.sqrt()).collect();
        let beta = 1.0 - 1.0 / (1.0 + lambda).sqrt();
        shrink_along(rows, &q, beta);
    }
}

/// z ← z − β q (qᵀ z) for every column of the rows (z = r/σ): value, parameters' and
/// effects' derivatives.
fn shrink_along(rows: &mut [Residual], q: &[f64], beta: f64) {
    let n_theta = rows.first().map_or(0, |r| r.d_theta.len());
    let (mut value, mut jac, mut theta) = (0.0, Row::zeros(), vec![0.0; n_theta]);
    for (r, qi) in rows.iter().zip(q) {
        let w = qi / r.sigma;
        value += w * r.value;
        jac += r.jacobian * w;
        for (t, d) in theta.iter_mut().zip(&r.d_theta) {
            *t += w * d;
        }
    }
    for (r, qi) in rows.iter_mut().zip(q) {
        let a = beta * qi * r.sigma;
        r.value -= a * value;
        r.jacobian -= jac * a;
        for (d, t) in r.d_theta.iter_mut().zip(&theta) {
            *d -= a * t;
        }
    }
}

/// Two orthonormal rows spanning the complement of the first two columns of `basis`
/// (orthonormal): Gram-Schmidt of the unit vector that keeps the most of itself, twice (of
/// the four, the best keeps at least 1/√2, then 1/2, so none is ever near zero).
pub(super) fn complement(basis: &nalgebra::Matrix4<f64>) -> [nalgebra::RowVector4<f64>; 2] {
    let mut found = [
        basis.column(0).into_owned(),
        basis.column(1).into_owned(),
        nalgebra::Vector4::zeros(),
        nalgebra::Vector4::zeros(),
    ];
    for slot in 2..4 {
        let rest = |e: usize| {
            let mut w = nalgebra::Vector4::zeros();
            w[e] = 1.0;
            for b in &found[..slot] {
                w -= b * b.dot(&w);
            }
            w
        };
        let best = (0..4)
            .map(rest)
            .max_by(|a, b| a.norm().total_cmp(&b.norm()))
            .unwrap_or_default();
        found[slot] = best.normalize();
    }
    [found[2].transpose(), found[3].transpose()]
}
