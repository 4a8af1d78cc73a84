//! The guides' frames, the joints and the loop-closure equations, with their derivatives in the
//! configuration and the parameters.

use super::config::{q_var, Config, PSI, X, Y};
use crate::params::{Guide, Model, Params, Rod, GAMMA2, N_PARAMS, RODS};
use nalgebra::{SMatrix, SVector, Vector2};

/// Guide frame of guide `g`: origin, direction e (along the guide), n (across).
#[inline]
pub fn guide_frame(p: &Params, g: Guide) -> (Vector2<f64>, Vector2<f64>, Vector2<f64>) {
    let (s, c) = p[g.gamma_index()].sin_cos();
    (
        Vector2::new(p[g.d_index()], 0.0),
        Vector2::new(-s, c),
        Vector2::new(c, s),
    )
}

/// Carrier joint B of `rod` for actuator position q.
#[inline]
pub fn carrier_joint(p: &Params, rod: &Rod, q: f64) -> Vector2<f64> {
    let (o, e, n) = guide_frame(p, rod.guide);
    o + n * p[rod.xb] + e * (q + p[rod.yb])
}

/// Platform joint A of `rod` for pose (x, y, ψ).
#[inline]
pub fn platform_joint(p: &Params, rod: &Rod, x: f64, y: f64, psi: f64) -> Vector2<f64> {
    let (s, c) = psi.sin_cos();
    let (xa, ya) = (p[rod.xa], p[rod.ya]);
    Vector2::new(x + c * xa - s * ya, y + s * xa + c * ya)
}

/// The five equations of a model on a configuration, and their derivatives.
#[derive(Clone, Copy, Debug)]
pub struct Closure {
    /// Residuals (mm² for rods, rad for the model-24 angle constraint).
    pub e: SVector<f64, 5>,
    /// ∂e/∂c.
    pub e_c: SMatrix<f64, 5, 7>,
}

/// Rods whose closure is an equation of the model: 1-4, then 5 for model 29.
pub(super) fn equation_rods(model: Model) -> &'static [Rod] {
    match model {
        Model::M24 => &RODS[..4],
        Model::M29 => &RODS[..5],
    }
}

/// What the equations of one configuration share: sin and cos of ψ, and both guides' frames
/// (each a sin_cos: computed once per evaluation, not once per rod and use).
pub(super) struct Trig {
    pub(super) psi: (f64, f64),
    pub(super) frames: [(Vector2<f64>, Vector2<f64>, Vector2<f64>); 2],
}

impl Trig {
    pub(super) fn new(p: &Params, c: &Config) -> Trig {
        Trig {
            psi: c[PSI].sin_cos(),
            frames: [guide_frame(p, Guide::G1), guide_frame(p, Guide::G2)],
        }
    }

    pub(super) fn frame(&self, g: Guide) -> (Vector2<f64>, Vector2<f64>, Vector2<f64>) {
        match g {
            Guide::G1 => self.frames[0],
            Guide::G2 => self.frames[1],
        }
    }
}

/// Residual of one rod's closure: |A − B|² − l², and the vector r = A − B.
#[inline]
pub(super) fn rod_residual(p: &Params, rod: &Rod, c: &Config, t: &Trig) -> (f64, Vector2<f64>) {
    let (s, co) = t.psi;
    let (xa, ya) = (p[rod.xa], p[rod.ya]);
    let a = Vector2::new(c[X] + co * xa - s * ya, c[Y] + s * xa + co * ya);
    let (o, e, n) = t.frame(rod.guide);
    let b = o + n * p[rod.xb] + e * (c[q_var(rod.actuator)] + p[rod.yb]);
    let r = a - b;
    (r.norm_squared() - p[rod.l] * p[rod.l], r)
}

/// Evaluate the model's equations and their configuration derivatives.
pub fn closure(p: &Params, model: Model, c: &Config) -> Closure {
    closure_with(p, model, c, &Trig::new(p, c))
}

/// [`closure`] with the configuration's trigonometry given.
pub(super) fn closure_with(p: &Params, model: Model, c: &Config, t: &Trig) -> Closure {
    let mut e = SVector::<f64, 5>::zeros();
    let mut e_c = SMatrix::<f64, 5, 7>::zeros();
    let (s, co) = t.psi;
    for (row, rod) in equation_rods(model).iter().enumerate() {
        let (f, r) = rod_residual(p, rod, c, t);
        let (_, dir, _) = t.frame(rod.guide);
        // dA/dψ = R'(ψ) a
        let da_dpsi = Vector2::new(
            -s * p[rod.xa] - co * p[rod.ya],
            co * p[rod.xa] - s * p[rod.ya],
        );
        e[row] = f;
        e_c[(row, X)] = 2.0 * r.x;
        e_c[(row, Y)] = 2.0 * r.y;
        e_c[(row, PSI)] = 2.0 * r.dot(&da_dpsi);
        e_c[(row, q_var(rod.actuator))] = -2.0 * r.dot(&dir);
    }
    if model == Model::M24 {
        e[4] = c[PSI] - p[GAMMA2];
        e_c[(4, PSI)] = 1.0;
    }
    Closure { e, e_c }
}

/// ∂e/∂p: derivatives of the model's equations with respect to the 29 parameters.
pub fn closure_params(p: &Params, model: Model, c: &Config) -> SMatrix<f64, 5, N_PARAMS> {
    closure_params_with(p, model, c, &Trig::new(p, c))
}

/// [`closure_params`] with the configuration's trigonometry given.
pub(super) fn closure_params_with(
    p: &Params,
    model: Model,
    c: &Config,
    t: &Trig,
) -> SMatrix<f64, 5, N_PARAMS> {
    let mut e_p = SMatrix::<f64, 5, N_PARAMS>::zeros();
    let (s, co) = t.psi;
    for (row, rod) in equation_rods(model).iter().enumerate() {
        let (_, r) = rod_residual(p, rod, c, t);
        let (_, dir, across) = t.frame(rod.guide);
        let along = c[q_var(rod.actuator)] + p[rod.yb];
        e_p[(row, rod.l)] = -2.0 * p[rod.l];
        e_p[(row, rod.xa)] = 2.0 * r.dot(&Vector2::new(co, s));
        e_p[(row, rod.ya)] = 2.0 * r.dot(&Vector2::new(-s, co));
        e_p[(row, rod.xb)] = -2.0 * r.dot(&across);
        e_p[(row, rod.yb)] = -2.0 * r.dot(&dir);
        e_p[(row, rod.guide.d_index())] = -2.0 * r.x;
        // dB/dγ = xb·e − (q + yb)·n, since dn/dγ = e and de/dγ = −n.
        let db_dgamma = dir * p[rod.xb] - across * along;
        e_p[(row, rod.guide.gamma_index())] = -2.0 * r.dot(&db_dgamma);
    }
    if model == Model::M24 {
        e_p[(4, GAMMA2)] = -1.0;
    }
    e_p
}

/// A guide's frame: origin, e (along), n (across).
pub(crate) type Frame = (Vector2<f64>, Vector2<f64>, Vector2<f64>);
/// Both guides' frames, computed once per call (with ψ's, three sin_cos in all).
pub(crate) type Frames = [Frame; 2];

/// Both guides' frames of a machine: two sin_cos, for callers that solve several models on
/// one machine per sample (the elastic model's rigid reference, its solve and its checks).
#[inline]
pub(crate) fn frames(p: &Params) -> Frames {
    [guide_frame(p, Guide::G1), guide_frame(p, Guide::G2)]
}
