//! The spring (lumped) elasto-geometric forward model: rods as axial springs, optional
//! carrier compliance along the guides, drives that hold their positions exactly.
//!
//! Unknowns z = (x, y, ψ, s1, s2, s3, s4): the platform pose and the four carrier positions
//! along their guides (same coordinate as the actuator positions q). The potential energy is
//!
//! V(z) = Σ_rods ½ k_i (|A_i − B_i(s)| − l_i)² + Σ_{active, compliant} ½ c_j (s_j − q_j)²
//!
//! and static equilibrium is ∇V = 0, except for an active drive with a rigid carrier, whose
//! equation is s_j = q_j (integral action: the encoder reads exactly its command). A drive in
//! follower mode exerts no force; its carrier slides freely and s_j is solved for. Newton with
//! the analytic Hessian (tangent stiffness, geometric-stiffness terms included) converges
//! quadratically from the rigid forward model of a pair of active drives.

use super::limits::{wrap_angle, Violation};
use crate::geometry::{self, frames, near, Frames, Subsystem};
use crate::params::{Guide, Model, Params, N_PARAMS, RODS};
use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

/// Nominal drive force: 100 % redundancy current, N.
pub const NOMINAL_DRIVE_FORCE_N: f64 = 8600.0;
/// Newton stops after a step whose largest component falls below this, mm (or rad): with
/// quadratic convergence the error left is of the order of its square (< 1e-12 mm).
pub const STEP_TOL: f64 = 1e-7;
/// Iteration cap of the equilibrium Newton.
pub const MAX_ITER: usize = 30;
/// Newton also stops after a step s_k that the quadratic convergence of the two last steps
/// puts this close to the root, mm: the next step would be about s_k·(s_k/s_(k−1))². From a
/// warm start the steps run 0.3 mm, 4e-5 mm, 6e-13 mm: the third only confirmed the second,
/// and its 6e-13 mm is round-off on coordinates of 10³ mm. It is taken only after a
/// contraction by [`CONTRACTION`] at least, where the convergence is quadratic.
const PREDICTED_TOL: f64 = 1e-11;
/// The contraction of the last step against the one before that the prediction of
/// [`PREDICTED_TOL`] needs.
const CONTRACTION: f64 = 1e-3;

/// Whether Newton may stop after `step`, with `previous` the step before it: below
/// [`STEP_TOL`], or quadratically converging to within [`PREDICTED_TOL`]. The first step
/// has no previous one (infinite): only [`STEP_TOL`] stops it.
fn converged(step: f64, previous: f64) -> bool {
    step < STEP_TOL
        || (previous.is_finite()
            && step <= CONTRACTION * previous
            && step * (step / previous).powi(2) < PREDICTED_TOL)
}

/// Default effective axial stiffness of each rod, N/mm (rod, its two joints and the carrier in
/// series). Chosen so that an incompatibility of 0.4 mm on one redundant drive (q3 offset by
/// 0.4 mm at the workspace centre, nominal parameters, rigid carriers) drives the most loaded
/// drive to about 100 % redundancy current, as the thesis reports (section 4.4): the model is
/// linear in the stiffness for small incompatibilities, so the value is the one that gives
/// 8,600 N there (see `core/tests/it/elastic_spring.rs::default_stiffness_gives_100_percent_for_0_4_mm`).
pub const DEFAULT_ROD_STIFFNESS_N_PER_MM: f64 = 97_700.0;

/// Stiffness of the spring model.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stiffness {
    /// Effective axial stiffness of rods 1..=5, N/mm.
    pub rod: [f64; 5],
    /// Stiffness of carriers 1..=4 along their guides (drive, ball screw/linear motor
    /// servo-stiffness and carrier in series), N/mm; `None` = rigid (the carrier sits exactly
    /// at its commanded position).
    pub carrier: [Option<f64>; 4],
}

impl Default for Stiffness {
    fn default() -> Self {
        Stiffness {
            rod: [DEFAULT_ROD_STIFFNESS_N_PER_MM; 5],
            carrier: [None; 4],
        }
    }
}

impl Stiffness {
    /// Every stiffness multiplied by `factor` (a compliance study: `factor` < 1 is softer).
    #[must_use]
    pub fn scaled(mut self, factor: f64) -> Self {
        for k in &mut self.rod {
            *k *= factor;
        }
        for c in self.carrier.iter_mut().flatten() {
            *c *= factor;
        }
        self
    }
}

/// Which drives are in follower mode (controller off, carrier free): `follower[i]` for q(i+1).
pub type Followers = [bool; 4];
/// All four drives position-controlled.
pub const ALL_ACTIVE: Followers = [false; 4];
/// q2, q3 followers (compatibility test, self-calibration).
pub const FOLLOWERS_23: Followers = [false, true, true, false];

/// An elasto-geometric solve that failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ElasticError {
    #[error("no pair of active drives among the viable subsystems: the platform is not held")]
    NotHeld,
    #[error("rigid start failed: {0}")]
    Start(#[from] geometry::GeometryError),
    #[error("equilibrium did not converge in {iterations} iterations (last step {step:.3e}, gradient {gradient:.3e} N)")]
    NotConverged {
        iterations: usize,
        step: f64,
        gradient: f64,
    },
    #[error("singular tangent stiffness at iteration {iteration}")]
    Singular { iteration: usize },
    #[error("non-finite input or state")]
    NonFinite,
    #[error("a rod length collapsed to zero")]
    Degenerate,
    #[error("implausible equilibrium: {0}")]
    Implausible(Violation),
}

/// Static equilibrium of the mechanism.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Equilibrium {
    /// Platform pose: TCP x, y (mm), angle ψ (rad).
    pub x: f64,
    pub y: f64,
    pub psi: f64,
    /// Carrier positions along their guides, mm (the commanded q for rigid active drives; the
    /// free position for followers).
    pub carrier: [f64; 4],
    /// Axial force of rods 1..=5, N, positive in tension.
    pub rod_force: [f64; 5],
    /// Drive forces f1..f4, N, positive when the drive pushes its carrier towards larger q; 0
    /// for a follower.
    pub drive_force: [f64; 4],
    /// Newton iterations.
    pub iterations: usize,
}

impl Equilibrium {
    /// Redundancy currents, % of the nominal 8,600 N, signed like the drive forces.
    pub fn current(&self) -> [f64; 4] {
        self.drive_force.map(|f| f / NOMINAL_DRIVE_FORCE_N * 100.0)
    }
    /// Largest |current| over the drives, %.
    pub fn max_current(&self) -> f64 {
        self.current().iter().fold(0.0, |m, c| m.max(c.abs()))
    }
    /// The unknown vector z = (x, y, ψ, s1..s4).
    pub fn z(&self) -> SVector<f64, 7> {
        SVector::<f64, 7>::from([
            self.x,
            self.y,
            self.psi,
            self.carrier[0],
            self.carrier[1],
            self.carrier[2],
            self.carrier[3],
        ])
    }
}

type V7 = SVector<f64, 7>;
type M7 = SMatrix<f64, 7, 7>;

/// Per-rod kinematic quantities at a state z.
struct RodState {
    /// Carrier index 0..=3 (unknown index 3 + carrier).
    carrier: usize,
    rho: f64,
    u: Vector2<f64>,
    delta: f64,
    /// A − P (platform joint relative to the TCP, rotated): ∂r/∂ψ = perp(A − P).
    arm: Vector2<f64>,
    e: Vector2<f64>,
    n: Vector2<f64>,
}

fn rod_state(p: &Params, i: usize, z: &V7) -> RodState {
    rod_state_with(p, &frames(p), z[2].sin_cos(), i, z)
}

#[inline]
fn rod_state_with(p: &Params, fr: &Frames, sc: (f64, f64), i: usize, z: &V7) -> RodState {
    let rod = &RODS[i];
    let (sn, cs) = sc;
    let (xa, ya) = (p[rod.xa], p[rod.ya]);
    let arm = Vector2::new(cs * xa - sn * ya, sn * xa + cs * ya);
    let a = Vector2::new(z[0], z[1]) + arm;
    let (o, e, n) = match rod.guide {
        Guide::G1 => fr[0],
        Guide::G2 => fr[1],
    };
    let s = z[3 + rod.actuator];
    let b = o + n * p[rod.xb] + e * (s + p[rod.yb]);
    let r = a - b;
    let rho = r.norm();
    let u = r / rho;
    RodState {
        carrier: rod.actuator,
        rho,
        u,
        delta: rho - p[rod.l],
        arm,
        e,
        n,
    }
}

/// Column vector Jᵀu for the rod: ∂ρ/∂z.
#[inline]
fn drho_dz(st: &RodState) -> V7 {
    let mut g = V7::zeros();
    g[0] = st.u.x;
    g[1] = st.u.y;
    // ∂r/∂ψ = R'(ψ)a = perp(arm) = (−arm.y, arm.x)
    g[2] = st.u.x * (-st.arm.y) + st.u.y * st.arm.x;
    g[3 + st.carrier] = -st.u.dot(&st.e);
    g
}

/// ∂r/∂z as a 2×7 matrix.
#[inline]
fn dr_dz(st: &RodState) -> SMatrix<f64, 2, 7> {
    let mut j = SMatrix::<f64, 2, 7>::zeros();
    j[(0, 0)] = 1.0;
    j[(1, 1)] = 1.0;
    j[(0, 2)] = -st.arm.y;
    j[(1, 2)] = st.arm.x;
    j[(0, 3 + st.carrier)] = -st.e.x;
    j[(1, 3 + st.carrier)] = -st.e.y;
    j
}

/// One rod's share of the gradient and the tangent stiffness. A rod's terms touch four
/// unknowns only (x, y, ψ, its carrier), so they are assembled on those: with d = ∂ρ/∂z = Jᵀu
/// and J = ∂r/∂z, k·d·dᵀ + (T/ρ)·Jᵀ(I − u·uᵀ)J = (k − T/ρ)·d·dᵀ + (T/ρ)·JᵀJ, a 4 × 4 block of
/// dot products instead of the dense 7 × 7 products (which cost most of a warm solve).
/// `M` = 4 assembles all four; `M` = 3 the pose's only, for a carrier whose row and column
/// the symmetric system replaces by its drive's constraint (see [`system`]): 6 entries of 10.
#[inline]
fn rod_terms<const M: usize>(st: &RodState, ki: f64, g: &mut V7, h: &mut M7) {
    let t = ki * st.delta;
    let idx = [0, 1, 2, 3 + st.carrier];
    // columns of J: ∂r/∂x, ∂r/∂y, ∂r/∂ψ = perp(arm), ∂r/∂s = −e
    let jc = [
        Vector2::new(1.0, 0.0),
        Vector2::new(0.0, 1.0),
        Vector2::new(-st.arm.y, st.arm.x),
        -st.e,
    ];
    let d = jc.map(|c| st.u.dot(&c));
    let (tr, kk) = (t / st.rho, ki - t / st.rho);
    for a in 0..M {
        g[idx[a]] += d[a] * t;
        for b in a..M {
            let v = kk * d[a] * d[b] + tr * jc[a].dot(&jc[b]);
            h[(idx[a], idx[b])] += v;
            if a != b {
                h[(idx[b], idx[a])] += v;
            }
        }
    }
    // ∂²r/∂ψ² = −arm
    h[(2, 2)] -= t * st.u.dot(&st.arm);
}

/// Gradient (generalised forces) and Hessian (tangent stiffness) of the system, with the rows of
/// rigid active carriers replaced by s_j − q_j = 0. With `symmetric`, their columns are zeroed
/// too, which keeps the matrix symmetric for the Newton step (valid because the solver keeps
/// s_j = q_j exactly, so those components of the step are 0); the sensitivities need the
/// unsymmetric form. Inlined: its 7 × 7 result was copied out on every Newton iteration.
/// `sc`: sin and cos of ψ = z[2].
#[inline]
fn system(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    (q, fol): (&[f64; 4], Followers),
    (z, sc): (&V7, (f64, f64)),
    symmetric: bool,
    (g, h): (&mut V7, &mut M7),
) -> bool {
    // whole assignments: nalgebra's fill walked the 49 entries one by one with index
    // arithmetic, a fifth of this function
    *g = V7::zeros();
    *h = M7::zeros();
    let mut ok = true;
    // drives whose row (and, symmetric, column) the constraint s_j − q_j = 0 replaces
    let fixed = |j: usize| !fol[j] && k.carrier[j].is_none();
    for i in 0..5 {
        let st = rod_state_with(p, fr, sc, i, z);
        if !(st.rho > 1e-9) {
            ok = false;
            continue;
        }
        if symmetric && fixed(st.carrier) {
            rod_terms::<3>(&st, k.rod[i], g, h);
        } else {
            rod_terms::<4>(&st, k.rod[i], g, h);
        }
    }
    for j in 0..4 {
        if fol[j] {
            continue;
        }
        let v = 3 + j;
        if let Some(c) = k.carrier[j] {
            g[v] += c * (z[v] - q[j]);
            h[(v, v)] += c;
        } else {
            g[v] = z[v] - q[j];
            // symmetric, the rods left this row and column out (rod_terms::<3>); else the
            // row is the constraint's and the columns keep the rods' terms
            if !symmetric {
                for col in 0..7 {
                    h[(v, col)] = 0.0;
                }
            }
            h[(v, v)] = 1.0;
        }
    }
    ok
}

/// Rigid start: the model-29 forward model of the first viable subsystem whose two drives are
/// active, at the commanded positions; its secant in ψ from `psi_warm` where given (the
/// previous sample's rigid ψ, never the elastic one: the same pose, in fewer closures).
pub(super) fn rigid_start(
    p: &Params,
    fr: &Frames,
    (q, fol): (&[f64; 4], Followers),
    psi_warm: Option<f64>,
) -> Result<V7, ElasticError> {
    for sub in Subsystem::VIABLE {
        if let Subsystem::Actuators(a, b) = sub {
            if fol[a] || fol[b] {
                continue;
            }
            let known = [q[a], q[b]];
            let s = match psi_warm {
                Some(w) => geometry::fgm29_from(p, fr, (a, b), known, w)?,
                None => geometry::fgm_with_frames(p, fr, Model::M29, sub, known)?,
            };
            let c = s.c;
            return Ok(V7::from([c[0], c[1], c[2], c[3], c[4], c[5], c[6]]));
        }
    }
    Err(ElasticError::NotHeld)
}

/// The raw solver without any plausibility check, from `previous` or else from the rigid
/// start: for studies of the solver and for tests of the checks. Its result may be a
/// non-physical branch; everything else goes through [`fegm_checked`].
pub fn fegm_unchecked(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    previous: Option<&Equilibrium>,
) -> Result<Equilibrium, ElasticError> {
    if !q.iter().all(|v| v.is_finite()) {
        return Err(ElasticError::NonFinite);
    }
    let fr = frames(p);
    let z0 = match previous {
        Some(prev) => warm_start(&q, followers, prev),
        None => rigid_start(p, &fr, (&q, followers), None)?,
    };
    solve_from(p, &fr, k, q, followers, z0).map(|sol| sol.eq)
}

/// The previous equilibrium with the active carriers moved to their new commands.
pub(super) fn warm_start(q: &[f64; 4], followers: Followers, previous: &Equilibrium) -> V7 {
    let mut z0 = previous.z();
    for j in 0..4 {
        if !followers[j] {
            z0[3 + j] = q[j];
        }
    }
    z0
}

/// An equilibrium with its rods' lengths and the platform's balance, from the pass over the
/// rods that computes its forces ([`finish`]): what the plausibility checks read, which
/// [`lengths_and_balance`] would compute again from the equilibrium's fields, the same rods
/// at the same state.
pub(super) struct Solved {
    pub(super) eq: Equilibrium,
    pub(super) lengths: [f64; 5],
    pub(super) balance: [f64; 3],
}

pub(super) fn solve_from(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    z: V7,
) -> Result<Solved, ElasticError> {
    newton(p, fr, k, (q, followers), z, converged)
}

/// Newton on the equilibrium from z, stopping where `stop(step, previous step)` says.
fn newton(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    (q, followers): ([f64; 4], Followers),
    mut z: V7,
    stop: impl Fn(f64, f64) -> bool,
) -> Result<Solved, ElasticError> {
    for j in 0..4 {
        if !followers[j] && k.carrier[j].is_none() {
            z[3 + j] = q[j];
        }
    }
    let mut last_step = f64::INFINITY;
    let mut gnorm = f64::INFINITY;
    // ψ's sine and cosine once, rotated for the iterates (`near`, sin_cos again beyond 1 mrad
    // from the start): three sin_cos per solve were a tenth of the checked warm fegm
    let anchor = (z[2], z[2].sin_cos());
    // the system's buffers, filled in place by every iteration
    let (mut g, mut h) = (V7::zeros(), M7::zeros());
    // the unknowns Newton moves: pose, followers' and compliant carriers
    let mut free = [0; 7];
    let mut n_free = 0;
    for (slot, v) in free
        .iter_mut()
        .zip((0..7).filter(|&v| v < 3 || followers[v - 3] || k.carrier[v - 3].is_some()))
    {
        *slot = v;
        n_free += 1;
    }
    for it in 0..MAX_ITER {
        let sc = near(anchor, z[2]);
        if !system(p, fr, k, (&q, followers), (&z, sc), true, (&mut g, &mut h)) {
            return Err(ElasticError::Degenerate);
        }
        gnorm = g.amax();
        if !gnorm.is_finite() {
            return Err(ElasticError::NonFinite);
        }
        // The tangent stiffness is symmetric and, near a stable equilibrium, positive definite:
        // Cholesky on the free unknowns, with LU of the whole matrix as the fallback.
        let step = match spd_step(&h, &g, &free[..n_free]) {
            Some(step) => step,
            _ => h
                .lu()
                .solve(&g)
                .ok_or(ElasticError::Singular { iteration: it })?,
        };
        z -= step;
        let previous = last_step;
        last_step = step.amax();
        if !last_step.is_finite() {
            return Err(ElasticError::NonFinite);
        }
        if stop(last_step, previous) {
            return Ok(finish(
                p,
                fr,
                k,
                followers,
                (&z, near(anchor, z[2])),
                it + 1,
            ));
        }
    }
    Err(ElasticError::NotConverged {
        iterations: MAX_ITER,
        step: last_step,
        gradient: gnorm,
    })
}

/// The Newton step H⁻¹g of the symmetric system, whose rows and columns of rigid active
/// carriers are unit ones (with g = 0 there once the carriers sit at their commands): a
/// Cholesky (LDLᵀ) on the `free` unknowns only, on the stack (3 of 7 unknowns when every
/// drive holds a rigid carrier, the servo-rate case, where the whole 7 × 7 factorisation cost
/// more than the rest of the iteration). None where H is not positive definite on them: the
/// caller then takes the LU of the whole matrix, as before.
fn spd_step(h: &M7, g: &V7, free: &[usize]) -> Option<V7> {
    // the pose is always free: 3 to 7 unknowns, each count its own factorisation with the
    // size known at compile time (unrolled, no bounds checks: with the count a run-time
    // value, the loops over 3 unknowns cost as much as the rest of a Newton iteration)
    match free.len() {
        3 => ldl_step::<3>(h, g, free),
        4 => ldl_step::<4>(h, g, free),
        5 => ldl_step::<5>(h, g, free),
        6 => ldl_step::<6>(h, g, free),
        7 => ldl_step::<7>(h, g, free),
        _ => None,
    }
}

/// [`spd_step`] on N free unknowns.
#[inline]
fn ldl_step<const N: usize>(h: &M7, g: &V7, free: &[usize]) -> Option<V7> {
    let free: &[usize; N] = free.try_into().ok()?;
    // the free block, gathered once
    let mut a = [[0.0f64; N]; N];
    for (row, &r) in a.iter_mut().zip(free) {
        for (v, &c) in row.iter_mut().zip(free) {
            *v = h[(r, c)];
        }
    }
    // LDLᵀ, the Cholesky without its roots: H positive definite on the free unknowns exactly
    // when every pivot d is; the pivots' reciprocals once, so that the factorisation and
    // both solves multiply (the divisions and roots in a chain were most of the step)
    let mut l = [[0.0f64; N]; N];
    let (mut d, mut inv_d) = ([0.0f64; N], [0.0f64; N]);
    for i in 0..N {
        for j in 0..i {
            let dot: f64 = (0..j).map(|k| l[i][k] * l[j][k] * d[k]).sum();
            l[i][j] = (a[i][j] - dot) * inv_d[j];
        }
        let di = a[i][i] - (0..i).map(|k| l[i][k] * l[i][k] * d[k]).sum::<f64>();
        if !(di > 0.0) {
            return None;
        }
        (d[i], inv_d[i]) = (di, 1.0 / di);
    }
    let mut y = [0.0f64; N];
    for i in 0..N {
        let dot: f64 = l[i][..i].iter().zip(&y[..i]).map(|(a, b)| a * b).sum();
        y[i] = g[free[i]] - dot;
    }
    for i in (0..N).rev() {
        let mut s = y[i] * inv_d[i];
        for k in i + 1..N {
            s -= l[k][i] * y[k];
        }
        y[i] = s;
    }
    // the fixed unknowns' rows are unit rows: their step is g there
    let mut step = *g;
    for (&v, &yi) in free.iter().zip(&y) {
        step[v] = yi;
    }
    Some(step)
}

/// The equilibrium at z (`sc`: sin and cos of ψ = z[2]) with its forces, the rods' lengths
/// and the platform's balance, in one pass over the rods.
fn finish(
    p: &Params,
    fr: &Frames,
    k: &Stiffness,
    fol: Followers,
    (z, sc): (&V7, (f64, f64)),
    iterations: usize,
) -> Solved {
    let mut rod_force = [0.0; 5];
    let mut drive_force = [0.0; 4];
    let (mut lengths, mut balance) = ([0.0; 5], [0.0; 3]);
    for (i, f) in rod_force.iter_mut().enumerate() {
        let st = rod_state_with(p, fr, sc, i, z);
        *f = k.rod[i] * st.delta;
        // Force of the drive on its carrier balances the rod's pull T·u along the guide.
        drive_force[st.carrier] -= *f * st.u.dot(&st.e);
        // as lengths_and_balance: the length, and the rod's force −T·u on the platform
        lengths[i] = st.rho;
        let on_platform = -st.u * *f;
        balance[0] += on_platform.x;
        balance[1] += on_platform.y;
        balance[2] += st.arm.x * on_platform.y - st.arm.y * on_platform.x;
    }
    for j in 0..4 {
        if fol[j] {
            drive_force[j] = 0.0;
        }
    }
    let eq = Equilibrium {
        x: z[0],
        y: z[1],
        // The solver works on sin/cos of ψ only: a warm start may drift by whole turns.
        psi: wrap_angle(z[2]),
        carrier: [z[3], z[4], z[5], z[6]],
        rod_force,
        drive_force,
        iterations,
    };
    Solved {
        eq,
        lengths,
        balance,
    }
}

/// Force and moment balance of the platform at an equilibrium: (Σ F_x, Σ F_y, Σ M_z about the
/// TCP), N and N·mm, from the rod forces alone (no external load).
pub fn platform_balance(p: &Params, eq: &Equilibrium) -> [f64; 3] {
    lengths_and_balance(p, &frames(p), eq).1
}

/// The rods' lengths |A − B| at an equilibrium's pose and carriers, and the platform's
/// balance ([`platform_balance`]), in one pass with the trigonometry once (three sin_cos for
/// the five rods): what the plausibility checks read.
pub(super) fn lengths_and_balance(
    p: &Params,
    fr: &Frames,
    eq: &Equilibrium,
) -> ([f64; 5], [f64; 3]) {
    let z = eq.z();
    let sc = z[2].sin_cos();
    let mut lengths = [0.0; 5];
    let mut out = [0.0; 3];
    for (i, rho) in lengths.iter_mut().enumerate() {
        let st = rod_state_with(p, fr, sc, i, &z);
        *rho = st.rho;
        // A rod in tension pulls the platform joint towards its carrier: force −T·u.
        let f = -st.u * eq.rod_force[i];
        out[0] += f.x;
        out[1] += f.y;
        out[2] += st.arm.x * f.y - st.arm.y * f.x;
    }
    (lengths, out)
}

/// Sensitivities of an equilibrium (implicit-function theorem on ∇V = 0).
#[derive(Clone, Copy, Debug)]
pub struct ElasticSensitivity {
    /// ∂(x, y, ψ)/∂(q1..q4).
    pub dpose_dq: SMatrix<f64, 3, 4>,
    /// ∂(x, y, ψ)/∂p (29 parameters).
    pub dpose_dp: SMatrix<f64, 3, N_PARAMS>,
    /// ∂(s1..s4)/∂(q1..q4): how followers' carriers move.
    pub dcarrier_dq: SMatrix<f64, 4, 4>,
}

/// One parameter's share in a rod's terms: (parameter index, ∂r/∂p, ∂J/∂p as (column,
/// vector) or none, ∂l/∂p).
type RodPartial = (usize, Vector2<f64>, Option<(usize, Vector2<f64>)>, f64);

/// ∂G/∂p of the equilibrium at `z`: the rod terms, only in the rows that are not replaced by
/// rigid constraints.
fn g_params(
    p: &Params,
    k: &Stiffness,
    followers: Followers,
    z: &SVector<f64, 7>,
) -> SMatrix<f64, 7, N_PARAMS> {
    let mut g_p = SMatrix::<f64, 7, N_PARAMS>::zeros();
    let (sn, cs) = z[2].sin_cos();
    for (i, rod) in RODS.iter().enumerate() {
        let st = rod_state(p, i, z);
        let ki = k.rod[i];
        let t = ki * st.delta;
        let d = drho_dz(&st);
        let j = dr_dz(&st);
        let proj = Matrix2::identity() - st.u * st.u.transpose();
        let s = z[3 + rod.actuator];
        let along = s + p[rod.yb];
        // (parameter index, ∂r/∂p, ∂J/∂p as (column, vector) or none, ∂l/∂p)
        let dr: [RodPartial; 7] = [
            (rod.l, Vector2::zeros(), None, 1.0),
            (
                rod.xa,
                Vector2::new(cs, sn),
                Some((2, Vector2::new(-sn, cs))),
                0.0,
            ),
            (
                rod.ya,
                Vector2::new(-sn, cs),
                Some((2, Vector2::new(-cs, -sn))),
                0.0,
            ),
            (rod.xb, -st.n, None, 0.0),
            (rod.yb, -st.e, None, 0.0),
            (rod.guide.d_index(), Vector2::new(-1.0, 0.0), None, 0.0),
            (
                rod.guide.gamma_index(),
                -(st.e * p[rod.xb] - st.n * along),
                Some((3 + rod.actuator, st.n)),
                0.0,
            ),
        ];
        for (pi, drp, djp, dl) in dr {
            let ddelta = st.u.dot(&drp) - dl;
            let mut col = d * (ki * ddelta);
            col += j.transpose() * (proj * drp) * (t / st.rho);
            if let Some((c, v)) = djp {
                col[c] += t * st.u.dot(&v);
            }
            for row in 0..7 {
                g_p[(row, pi)] += col[row];
            }
        }
    }
    for j in 0..4 {
        if !followers[j] && k.carrier[j].is_none() {
            for c in 0..N_PARAMS {
                g_p[(3 + j, c)] = 0.0;
            }
        }
    }
    g_p
}

/// Analytic sensitivities of `eq` (solved for `q`, `followers`).
pub fn sensitivity(
    p: &Params,
    k: &Stiffness,
    q: [f64; 4],
    followers: Followers,
    eq: &Equilibrium,
) -> Result<ElasticSensitivity, ElasticError> {
    let z = eq.z();
    let (mut g, mut h) = (V7::zeros(), M7::zeros());
    system(
        p,
        &frames(p),
        k,
        (&q, followers),
        (&z, z[2].sin_cos()),
        false,
        (&mut g, &mut h),
    );
    let lu = h.lu();
    // ∂G/∂q: only the rows of active carriers depend on q.
    let mut g_q = SMatrix::<f64, 7, 4>::zeros();
    for j in 0..4 {
        if !followers[j] {
            g_q[(3 + j, j)] = match k.carrier[j] {
                Some(c) => -c,
                None => -1.0,
            };
        }
    }
    let g_p = g_params(p, k, followers, &z);
    let dz_dq = lu
        .solve(&g_q)
        .ok_or(ElasticError::Singular { iteration: 0 })?;
    let dz_dp = lu
        .solve(&g_p)
        .ok_or(ElasticError::Singular { iteration: 0 })?;
    Ok(ElasticSensitivity {
        dpose_dq: -dz_dq.fixed_rows::<3>(0).into_owned(),
        dpose_dp: -dz_dp.fixed_rows::<3>(0).into_owned(),
        dcarrier_dq: -dz_dq.fixed_rows::<4>(3).into_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elastic::fegm;

    /// The dense rod terms the solver assembled before [`rod_terms`]: k·d·dᵀ + (T/ρ)·JᵀPJ.
    fn dense_rod_terms(p: &Params, fr: &Frames, k: &Stiffness, z: &V7) -> (V7, M7) {
        let (mut g, mut h) = (V7::zeros(), M7::zeros());
        for i in 0..5 {
            let st = rod_state_with(p, fr, z[2].sin_cos(), i, z);
            let t = k.rod[i] * st.delta;
            let d = drho_dz(&st);
            g += d * t;
            let j = dr_dz(&st);
            let proj = Matrix2::identity() - st.u * st.u.transpose();
            h += d * d.transpose() * k.rod[i];
            h += j.transpose() * proj * j * (t / st.rho);
            h[(2, 2)] += t * (-st.u.dot(&st.arm));
        }
        (g, h)
    }

    /// The sparse assembly ([`rod_terms`]) is the dense one, and the Cholesky on the free
    /// unknowns ([`spd_step`]) gives nalgebra's Cholesky step on the whole matrix, to round-off:
    /// at equilibria and off them, rigid and compliant carriers, all drives active and q2, q3
    /// followers. So the warm fegm's iterates, and its result, are those of before.
    #[test]
    fn sparse_assembly_and_free_cholesky_match_the_dense_forms() {
        let mut p = Params::nominal();
        for (n, i) in [0, 3, 7, 12, 20, 24, 26].into_iter().enumerate() {
            p[i] += 0.03 * (n as f64 + 1.0);
        }
        let fr = frames(&p);
        let compliant = Stiffness {
            carrier: [Some(4e4), None, Some(6e4), Some(5e4)],
            ..Stiffness::default()
        };
        let mut steps = 0;
        for k in [Stiffness::default(), compliant] {
            for (x, y) in [(0.0, 1700.0), (-200.0, 1100.0), (250.0, 2300.0)] {
                let q = geometry::igm(&p, Model::M29, x, y).unwrap().q();
                let q = [q[0], q[1], q[2] + 0.2, q[3]];
                for fol in [ALL_ACTIVE, FOLLOWERS_23] {
                    let eq = fegm(&p, &k, q, fol).unwrap();
                    for dz in [0.0, 0.3] {
                        let z = eq.z() + V7::from([dz, -dz, 1e-3 * dz, 0.0, dz, -dz, 0.0]);
                        let (g0, h0) = dense_rod_terms(&p, &fr, &k, &z);
                        let (mut g1, mut h1) = (V7::zeros(), M7::zeros());
                        assert!(system(
                            &p,
                            &fr,
                            &k,
                            (&q, [true; 4]),
                            (&z, z[2].sin_cos()),
                            true,
                            (&mut g1, &mut h1)
                        ));
                        assert!(
                            (g1 - g0).amax() <= 1e-9 * g0.amax().max(1.0),
                            "{g1} vs {g0}"
                        );
                        assert!((h1 - h0).amax() <= 1e-9 * h0.amax(), "{h1} vs {h0}");
                        let mut zq = z;
                        for j in (0..4).filter(|&j| !fol[j] && k.carrier[j].is_none()) {
                            zq[3 + j] = q[j];
                        }
                        let (mut g, mut h) = (V7::zeros(), M7::zeros());
                        system(
                            &p,
                            &fr,
                            &k,
                            (&q, fol),
                            (&zq, zq[2].sin_cos()),
                            true,
                            (&mut g, &mut h),
                        );
                        // the symmetric system: the dense terms with the rigid drives' rows
                        // and columns replaced by their constraints
                        let (mut gd, mut hd) = dense_rod_terms(&p, &fr, &k, &zq);
                        for j in (0..4).filter(|&j| !fol[j]) {
                            let v = 3 + j;
                            if let Some(c) = k.carrier[j] {
                                gd[v] += c * (zq[v] - q[j]);
                                hd[(v, v)] += c;
                            } else {
                                gd[v] = zq[v] - q[j];
                                hd.row_mut(v).fill(0.0);
                                hd.column_mut(v).fill(0.0);
                                hd[(v, v)] = 1.0;
                            }
                        }
                        assert!((g - gd).amax() <= 1e-9 * gd.amax().max(1.0), "{g} vs {gd}");
                        assert!((h - hd).amax() <= 1e-9 * hd.amax(), "{h} vs {hd}");
                        let free: Vec<usize> = (0..7)
                            .filter(|&v| v < 3 || fol[v - 3] || k.carrier[v - 3].is_some())
                            .collect();
                        let ours = spd_step(&h, &g, &free).unwrap();
                        let want = h.cholesky().unwrap().solve(&g);
                        assert!((ours - want).amax() <= 1e-9 * want.amax().max(1e-9));
                        steps += 1;
                    }
                }
            }
        }
        assert_eq!(steps, 24);
        // not positive definite on the free unknowns: None, the caller's LU decides
        let h = -M7::identity();
        assert!(spd_step(&h, &V7::repeat(1.0), &[0, 1, 2]).is_none());
    }
}
