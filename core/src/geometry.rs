//! Loop-closure geometry of the Scissors-Kinematics: igm, fgm of every viable subsystem, rgm.
//!
//! Every geometric model of the thesis is one square system. The configuration has seven
//! variables c = (x, y, ψ, q1, q2, q3, q4); the model imposes five equations: the loop
//! closures of rods 1-4 plus, for model 29, rod 5 or, for model 24, the perfect-parallel-holder
//! constraint ψ = γ2. Knowing two configuration variables fixes the other five:
//! - igm: (x, y) known,
//! - fgm of a non-redundant subsystem: two actuators known ((q1,q4), (q3,q4), (q2,q3), (q1,q2)),
//! - rgm: (q1, q4) known, (q2, q3) read off the same solution.
//!
//! The solve starts from the analytic model-24 answer (seed eq. 4.6 and annex A) and polishes
//! with Newton; its sensitivities to the parameters and to the known variables come from the
//! implicit function theorem, dc_u = −E_u⁻¹ (E_p dp + E_k dc_k), so calibration Jacobians are
//! analytic and exact (they are checked against finite differences in the tests).

use crate::params::{Guide, Model, Params, Rod, GAMMA2, N_PARAMS, RODS};
use nalgebra::{SMatrix, SVector, Vector2, Vector3};

/// Configuration variable indexes.
pub const X: usize = 0;
pub const Y: usize = 1;
pub const PSI: usize = 2;
/// Index of actuator `i` (0..=3 for q1..q4) in the configuration.
pub const fn q_var(i: usize) -> usize {
    3 + i
}

/// Configuration (x, y, ψ, q1, q2, q3, q4), mm and rad.
pub type Config = SVector<f64, 7>;
/// Sensitivity of the configuration to the 29 parameters.
pub type ParamJacobian = SMatrix<f64, 7, N_PARAMS>;

/// Residual tolerance of the Newton solves on the loop closures |A−B|² − l², in mm²
/// (the thesis stops at |F| < 1e-8 mm²; that is 5e-12 mm on a 950 mm rod).
pub const TOL_MM2: f64 = 1e-8;
/// Iteration cap of the Newton solves (the thesis reports 4-5 iterations).
pub const MAX_ITER: usize = 20;
/// Below this ratio |det| / Π‖rows‖ the system counts as singular.
const SINGULAR_RATIO: f64 = 1e-7;

/// A geometric solve that failed: typed, never a NaN.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeometryError {
    #[error("rod {rod} cannot reach its carrier guide at this pose (discriminant {discriminant:.3e} mm²)")]
    Unreachable { rod: usize, discriminant: f64 },
    #[error("rods {a} and {b} do not intersect for these actuator positions (circles {gap:.3e} mm apart)")]
    NoIntersection { a: usize, b: usize, gap: f64 },
    #[error("the subsystem {subsystem} is singular at this pose (conditioning ratio {ratio:.2e})")]
    Singular { subsystem: Subsystem, ratio: f64 },
    #[error("{what} did not converge in {iterations} iterations (residual {residual:.3e} mm²)")]
    NotConverged {
        what: &'static str,
        iterations: usize,
        residual: f64,
    },
    #[error("the solution leaves the assembly mode of rod {rod}")]
    AssemblyMode { rod: usize },
    #[error("non-finite input")]
    NonFinite,
}

/// A pair of known configuration variables: the inputs of a geometric model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Subsystem {
    /// (x, y) known: the inverse geometric model.
    Tcp,
    /// Two actuators known: a forward model of a non-redundant subsystem (0-based indexes, a < b).
    Actuators(usize, usize),
}

impl Subsystem {
    /// The non-redundant subsystem the thesis uses for fgm and rgm: (q1, q4).
    pub const NR: Subsystem = Subsystem::Actuators(0, 3);
    /// The viable forward subsystems ((q2,q4) and (q1,q3) are singular at x = 0).
    pub const VIABLE: [Subsystem; 4] = [
        Subsystem::Actuators(0, 3),
        Subsystem::Actuators(2, 3),
        Subsystem::Actuators(1, 2),
        Subsystem::Actuators(0, 1),
    ];

    fn known(self) -> [usize; 2] {
        match self {
            Subsystem::Tcp => [X, Y],
            Subsystem::Actuators(a, b) => [q_var(a), q_var(b)],
        }
    }

    fn unknown(self) -> [usize; 5] {
        let k = self.known();
        let mut out = [0; 5];
        let mut n = 0;
        for v in 0..7 {
            if !k.contains(&v) {
                out[n] = v;
                n += 1;
            }
        }
        out
    }
}

impl std::fmt::Display for Subsystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Subsystem::Tcp => write!(f, "(x, y)"),
            Subsystem::Actuators(a, b) => write!(f, "(q{}, q{})", a + 1, b + 1),
        }
    }
}

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
fn equation_rods(model: Model) -> &'static [Rod] {
    match model {
        Model::M24 => &RODS[..4],
        Model::M29 => &RODS[..5],
    }
}

/// What the equations of one configuration share: sin and cos of ψ, and both guides' frames
/// (each a sin_cos: computed once per evaluation, not once per rod and use).
struct Trig {
    psi: (f64, f64),
    frames: [(Vector2<f64>, Vector2<f64>, Vector2<f64>); 2],
}

impl Trig {
    fn new(p: &Params, c: &Config) -> Trig {
        Trig {
            psi: c[PSI].sin_cos(),
            frames: [guide_frame(p, Guide::G1), guide_frame(p, Guide::G2)],
        }
    }

    fn frame(&self, g: Guide) -> (Vector2<f64>, Vector2<f64>, Vector2<f64>) {
        match g {
            Guide::G1 => self.frames[0],
            Guide::G2 => self.frames[1],
        }
    }
}

/// Residual of one rod's closure: |A − B|² − l², and the vector r = A − B.
#[inline]
fn rod_residual(p: &Params, rod: &Rod, c: &Config, t: &Trig) -> (f64, Vector2<f64>) {
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
fn closure_with(p: &Params, model: Model, c: &Config, t: &Trig) -> Closure {
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
fn closure_params_with(
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

/// A solved configuration and how it was reached.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    pub c: Config,
    /// Newton iterations after the analytic start.
    pub iterations: usize,
    /// Largest closure residual at the end, mm².
    pub residual: f64,
}

impl Solution {
    pub fn x(&self) -> f64 {
        self.c[X]
    }
    pub fn y(&self) -> f64 {
        self.c[Y]
    }
    pub fn psi(&self) -> f64 {
        self.c[PSI]
    }
    /// Actuator positions q1..q4.
    pub fn q(&self) -> [f64; 4] {
        [self.c[3], self.c[4], self.c[5], self.c[6]]
    }
}

/// Actuator position of one rod for a platform pose (seed eq. 4.6 with the assembly mode k).
pub fn rod_igm(p: &Params, rod: &Rod, x: f64, y: f64, psi: f64) -> Result<f64, GeometryError> {
    rod_igm_at(p, rod, x, y, psi.sin_cos(), guide_frame(p, rod.guide))
}

/// [`rod_igm`] with sin and cos of ψ and the rod's guide frame given (computed once by a
/// caller that needs them for several rods or several calls).
fn rod_igm_at(
    p: &Params,
    rod: &Rod,
    x: f64,
    y: f64,
    psi: (f64, f64),
    frame: (Vector2<f64>, Vector2<f64>, Vector2<f64>),
) -> Result<f64, GeometryError> {
    let reach = rod_reach(p, rod, (x, y), psi, frame)?;
    Ok(reach.we + rod.k * reach.disc.sqrt() - p[rod.yb])
}

/// Eq. 4.6 for one rod, up to the root: its platform joint A, and along the guide `w·e` and
/// the discriminant under the root.
struct Reach {
    a: Vector2<f64>,
    we: f64,
    disc: f64,
}

/// [`Reach`] of `rod` at the platform pose (x, y) with sin and cos of ψ, in its guide's
/// frame (origin, along, across); `Unreachable` where the discriminant is negative.
fn rod_reach(
    p: &Params,
    rod: &Rod,
    (x, y): (f64, f64),
    (s, c): (f64, f64),
    (o, e, n): (Vector2<f64>, Vector2<f64>, Vector2<f64>),
) -> Result<Reach, GeometryError> {
    let (xa, ya) = (p[rod.xa], p[rod.ya]);
    let a = Vector2::new(x + c * xa - s * ya, y + s * xa + c * ya);
    let w = a - o - n * p[rod.xb];
    let we = w.dot(&e);
    let l = p[rod.l];
    let disc = we * we - w.norm_squared() + l * l;
    if !(disc >= 0.0) {
        return Err(GeometryError::Unreachable {
            rod: rod.number,
            discriminant: disc,
        });
    }
    Ok(Reach { a, we, disc })
}

/// Analytic model-24 start for the inverse model: ψ = γ2, each rod by eq. 4.6.
fn igm_start(p: &Params, x: f64, y: f64) -> Result<Config, GeometryError> {
    igm_at_psi(p, x, y, p[GAMMA2])
}

/// The configuration of TCP (x, y) at platform angle ψ: each rod by eq. 4.6.
fn igm_at_psi(p: &Params, x: f64, y: f64, psi: f64) -> Result<Config, GeometryError> {
    let mut c = Config::zeros();
    c[X] = x;
    c[Y] = y;
    c[PSI] = psi;
    let t = Trig::new(p, &c);
    for rod in &RODS[..4] {
        c[q_var(rod.actuator)] = rod_igm_at(p, rod, x, y, t.psi, t.frame(rod.guide))?;
    }
    Ok(c)
}

/// Model-29 start for the inverse model: ψ solves rod 5's closure with q4 from rod 4 (the
/// two rods share carrier 4), a one-dimensional secant iteration from γ2, then each rod by
/// eq. 4.6. Newton then finds every equation closed at its first evaluation instead of
/// taking three 5 × 5 steps; where the secant does not settle, Newton starts from its last
/// iterate and does the work, and where it leaves the reachable poses, from the model-24
/// start as before.
fn igm29_start(p: &Params, x: f64, y: f64) -> Result<Config, GeometryError> {
    match rod5_settled(p, x, y) {
        Ok(c) if c.iter().all(|v| v.is_finite()) => Ok(c),
        _ => igm_start(p, x, y),
    }
}

/// The configuration with ψ settled on rod 5's closure (see [`igm29_start`]).
fn rod5_settled(p: &Params, x: f64, y: f64) -> Result<Config, GeometryError> {
    let (psi, _) = settled_psi(p, x, y, guide_frame(p, RODS[4].guide))?;
    igm_at_psi(p, x, y, psi)
}

/// Where the secant in ψ stops: rod 5's closure |A − B|² − l² within a tenth of the solver's
/// tolerance. Its round-off is a few ulps of l² ≈ 10⁶ mm² (2e-10 mm²), so a tighter bound
/// would only be met by chance; ψ is then within 1e-17 rad of the root (the closure moves by
/// about 1.6e8 mm² per rad).
const SETTLED_MM2: f64 = 0.1 * TOL_MM2;

/// ψ closing rod 5's loop with q4 from rod 4 (`frame`: their guide's), by a secant iteration
/// in ψ from γ2; with its sine and cosine.
fn settled_psi(
    p: &Params,
    x: f64,
    y: f64,
    frame: (Vector2<f64>, Vector2<f64>, Vector2<f64>),
) -> Result<(f64, (f64, f64)), GeometryError> {
    let (rod4, rod5) = (&RODS[3], &RODS[4]);
    // rods 4 and 5 share guide 2: its frame once, one sin_cos per ψ tried
    let (o, e, n) = frame;
    let rod5_closure = |sc: (f64, f64)| -> Result<f64, GeometryError> {
        let (s, c) = sc;
        let q4 = rod_igm_at(p, rod4, x, y, (s, c), frame)?;
        let b = o + n * p[rod5.xb] + e * (q4 + p[rod5.yb]);
        let (xa, ya) = (p[rod5.xa], p[rod5.ya]);
        let r = Vector2::new(x + c * xa - s * ya, y + s * xa + c * ya) - b;
        Ok(r.norm_squared() - p[rod5.l] * p[rod5.l])
    };
    secant_psi(p[GAMMA2], (n.y, n.x), rod5_closure)
}

/// The secant in ψ from `gamma2` (and γ2 + 1e-6 rad) on a closure g(sin ψ, cos ψ), mm²; with
/// the sine and cosine of where it stops ([`secant_from`]). `gamma2_sc`: γ2's sine and
/// cosine, which guide 2's frame holds (n = (cos γ2, sin γ2), the same `sin_cos`): one
/// `sin_cos` less per solve.
fn secant_psi<E>(
    gamma2: f64,
    gamma2_sc: (f64, f64),
    g: impl Fn((f64, f64)) -> Result<f64, E>,
) -> Result<(f64, (f64, f64)), E> {
    let psi1 = gamma2 + 1e-6;
    // ψ1's sine and cosine before g(ψ0), the order this had before the shared loop: the
    // other one cost the model-29 igm 5 ns (1.5 %) in the bench
    let sc1 = psi1.sin_cos();
    let g0 = g(gamma2_sc)?;
    secant_from(f64::sin_cos, (gamma2, g0), (psi1, sc1), g)
}

/// ψ from a warm start ψw (the previous sample's): one Newton step on the closure with its
/// analytic slope (`g_slope`: g and ∂g/∂ψ), then the secant through ψw and that step
/// ([`secant_from`]). Where the secant from ψw + 1e-6 rad took three closures (ψ moves by
/// 1e-8 to 1e-7 rad per servo sample), this takes two: Newton leaves e1 = C·e0² (C =
/// g″/2g′), the secant through both then C·e0·e1, whose value |g1|·|g1/g0| predicts, far
/// below [`SETTLED_MM2`]. Both stop within the closure's round-off (a few 1e-10 mm² on a
/// slope of 6e5 mm²/rad), so ψ agrees with the secant's from γ2 to a few 1e-15 rad (1e-12
/// mm at the joints). ψw's sine and cosine are the only ones computed: the iterates
/// within [`WARM_PSI_RAD`] of it rotate them ([`near`]). A ψw that already closes the loop
/// is returned as it is.
fn newton_secant_psi<E>(
    warm: f64,
    g_slope: impl Fn((f64, f64)) -> Result<(f64, f64), E>,
    g: impl Fn((f64, f64)) -> Result<f64, E>,
) -> Result<(f64, (f64, f64)), E> {
    let anchor = (warm, warm.sin_cos());
    let (g0, slope) = g_slope(anchor.1)?;
    if !(g0.abs() >= SETTLED_MM2) {
        return Ok(anchor);
    }
    let psi1 = warm - g0 / slope;
    secant_from(
        |psi| near(anchor, psi),
        (warm, g0),
        (psi1, near(anchor, psi1)),
        g,
    )
}

/// The secant in ψ through (ψ0, g0) and ψ1 (with its sine and cosine), on a closure
/// g(sin ψ, cos ψ), mm², with `trig` the sine and cosine of an iterate; with those of where
/// it stops: |g| below [`SETTLED_MM2`], or an iterate whose value the two last ones put
/// below it. The secant's contraction only grows (e_(n+1)/e_n = (e_n/e_(n−1))·(e_(n−1)/e_(n−2)) asymptotically), so
/// |g_n|·|g_n/g_(n−1)| bounds the next value, and evaluating it would only confirm it (one
/// closure of five); the caller's closed checks verify the residual of the configuration it
/// builds there all the same.
fn secant_from<E>(
    trig: impl Fn(f64) -> (f64, f64),
    (mut psi0, mut g0): (f64, f64),
    (mut psi1, mut sc1): (f64, (f64, f64)),
    g: impl Fn((f64, f64)) -> Result<f64, E>,
) -> Result<(f64, (f64, f64)), E> {
    let mut g1 = g(sc1)?;
    for _ in 0..8 {
        if !(g1.abs() >= SETTLED_MM2) || g1.total_cmp(&g0).is_eq() {
            break;
        }
        let psi2 = psi1 - g1 * (psi1 - psi0) / (g1 - g0);
        let predicted = g1.abs() * (g1 / g0).abs();
        (psi0, g0) = (psi1, g1);
        psi1 = psi2;
        sc1 = trig(psi1);
        if predicted < SETTLED_MM2 {
            break;
        }
        g1 = g(sc1)?;
    }
    Ok((psi1, sc1))
}

/// sin and cos of ψ from those of a nearby ψa (`anchor`): ψa's rotated by d = ψ − ψa, whose
/// sine and cosine are their series to d⁵ and d⁶ (the next terms below 1e-24 for |d| ≤
/// [`WARM_PSI_RAD`], far under an ulp); `sin_cos` where ψ is farther.
pub(crate) fn near((psi_a, (sa, ca)): (f64, (f64, f64)), psi: f64) -> (f64, f64) {
    let d = psi - psi_a;
    if !(d.abs() <= WARM_PSI_RAD) {
        return psi.sin_cos();
    }
    let d2 = d * d;
    let sd = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0));
    let cd = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0));
    (sa * cd + ca * sd, ca * cd - sa * sd)
}

/// The model-29 inverse model without the general solver: ψ settled on rod 5's closure
/// ([`settled_psi`]), each rod by eq. 4.6 with the trigonometry once, and what Newton and
/// [`solve`] would then check, checked here in closed form: every loop closed (largest
/// residual below [`TOL_MM2`]), the assembly mode of the five rods, and the conditioning.
/// The unknowns (ψ, q1..q4) enter rod i's closure through ψ and its own drive only (rod 5
/// through q4), so the determinant is d1·d2·d3·(a4·d5 − a5·d4) with a = ∂e/∂ψ and
/// d = ∂e/∂q, and the normalised ratio of [`check_conditioning`] follows from a and d alone.
/// None where any check fails or the secant does not settle: the general solver then
/// decides, with its errors.
fn igm29(p: &Params, x: f64, y: f64) -> Option<Solution> {
    let frames = [guide_frame(p, Guide::G1), guide_frame(p, Guide::G2)];
    let (psi, (s, co)) = settled_psi(p, x, y, frames[1]).ok()?;
    let mut c = Config::zeros();
    (c[X], c[Y], c[PSI]) = (x, y, psi);
    let (mut a, mut d) = ([0.0; 5], [0.0; 5]);
    let mut residual: f64 = 0.0;
    for (i, rod) in RODS.iter().enumerate() {
        let ((o, e, n), side) = match rod.guide {
            Guide::G1 => (frames[0], -1.0),
            Guide::G2 => (frames[1], 1.0),
        };
        let (xa, ya) = (p[rod.xa], p[rod.ya]);
        let pa = Vector2::new(x + co * xa - s * ya, y + s * xa + co * ya);
        let q = if i < 4 {
            let q = rod_igm_at(p, rod, x, y, (s, co), (o, e, n)).ok()?;
            c[q_var(rod.actuator)] = q;
            q
        } else {
            c[q_var(rod.actuator)]
        };
        // B − A (the assembly mode reads it), A − B (the closure's derivatives)
        let ba = o + n * p[rod.xb] + e * (q + p[rod.yb]) - pa;
        if !(rod.k * ba.dot(&e) > 0.0 && side * ba.dot(&n) > 0.0) {
            return None;
        }
        let f = ba.norm_squared() - p[rod.l] * p[rod.l];
        residual = residual.max(f.abs());
        let da_dpsi = Vector2::new(-s * xa - co * ya, co * xa - s * ya);
        a[i] = -2.0 * ba.dot(&da_dpsi);
        d[i] = 2.0 * ba.dot(&e);
    }
    if !(residual < TOL_MM2) || conditioning29(&a, &d) <= SINGULAR_RATIO {
        return None;
    }
    Some(Solution {
        c,
        iterations: 0,
        residual,
    })
}

/// [`check_conditioning`]'s ratio for the model-29 inverse model's ∂e/∂(ψ, q1..q4), from
/// a = ∂e/∂ψ and d = ∂e/∂q of the five rods (see [`igm29`]); NaN counts as singular.
fn conditioning29(a: &[f64; 5], d: &[f64; 5]) -> f64 {
    let na = a.iter().map(|v| v * v).sum::<f64>().sqrt();
    let n4 = (d[3] * d[3] + d[4] * d[4]).sqrt();
    if !(na > 0.0 && n4 > 0.0 && d[..3].iter().all(|&v| v != 0.0)) {
        return 0.0;
    }
    let det = (a[3] * d[4] - a[4] * d[3]).abs() / (na * n4);
    let row = |u: f64, v: f64| (u * u + v * v).sqrt();
    let norms = row(a[0] / na, 1.0)
        * row(a[1] / na, 1.0)
        * row(a[2] / na, 1.0)
        * row(a[3] / na, d[3] / n4)
        * row(a[4] / na, d[4] / n4);
    det / norms
}

/// Analytic model-24 start for a forward model: intersection of the two rods' circles
/// (annex A) with ψ = γ2, keeping the assembly mode, then the other actuators by eq. 4.6.
fn fgm_start(p: &Params, a: usize, b: usize, qa: f64, qb: f64) -> Result<Config, GeometryError> {
    let psi = p[GAMMA2];
    // rods 1-4 hang on actuators q1-q4 in order
    let (ra, rb) = (&RODS[a], &RODS[b]);
    // Centre of the TCP circle of a rod: B − R(ψ)·a.
    let centre =
        |rod: &Rod, q: f64| carrier_joint(p, rod, q) - (platform_joint(p, rod, 0.0, 0.0, psi));
    let (ca, cb) = (centre(ra, qa), centre(rb, qb));
    let (la, lb) = (p[ra.l], p[rb.l]);
    let d_vec = cb - ca;
    let d = d_vec.norm();
    let along = (la * la - lb * lb + d * d) / (2.0 * d);
    let h2 = la * la - along * along;
    if !(h2 >= 0.0) || d == 0.0 {
        return Err(GeometryError::NoIntersection {
            a: ra.number,
            b: rb.number,
            gap: -h2,
        });
    }
    let u = d_vec / d;
    let perp = Vector2::new(-u.y, u.x);
    let base = ca + u * along;
    let h = h2.sqrt();
    for cand in [base + perp * h, base - perp * h] {
        if in_assembly_mode(p, ra, cand, psi, qa) && in_assembly_mode(p, rb, cand, psi, qb) {
            let mut c = Config::zeros();
            c[X] = cand.x;
            c[Y] = cand.y;
            c[PSI] = psi;
            for rod in &RODS[..4] {
                let i = rod.actuator;
                c[q_var(i)] = if i == a {
                    qa
                } else if i == b {
                    qb
                } else {
                    rod_igm(p, rod, cand.x, cand.y, psi)?
                };
            }
            return Ok(c);
        }
    }
    Err(GeometryError::AssemblyMode { rod: ra.number })
}

/// Assembly mode of the Scissors-Kinematics: carriers 1, 2 above their platform joints and
/// 3, 4, 5 below (along the guide), and every carrier on the outer side of its platform joint
/// (across the guide: guide 2 to the right, guide 1 to the left).
fn in_assembly_mode(p: &Params, rod: &Rod, tcp: Vector2<f64>, psi: f64, q: f64) -> bool {
    let mut c = Config::zeros();
    (c[X], c[Y], c[PSI], c[q_var(rod.actuator)]) = (tcp.x, tcp.y, psi, q);
    rod_in_assembly_mode(p, rod, &c, &Trig::new(p, &c))
}

/// [`in_assembly_mode`] of `rod` in configuration `c`, with its trigonometry given.
fn rod_in_assembly_mode(p: &Params, rod: &Rod, c: &Config, t: &Trig) -> bool {
    let (_, e, n) = t.frame(rod.guide);
    let (_, r) = rod_residual(p, rod, c, t);
    // r = A − B; the test reads B − A
    let r = -r;
    let side = match rod.guide {
        Guide::G1 => -1.0,
        Guide::G2 => 1.0,
    };
    rod.k * r.dot(&e) > 0.0 && side * r.dot(&n) > 0.0
}

/// Solve the model's five equations for the five unknowns of `sub`, from `start`.
fn newton(
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

fn select_columns(m: &SMatrix<f64, 5, 7>, cols: &[usize; 5]) -> SMatrix<f64, 5, 5> {
    SMatrix::<f64, 5, 5>::from_fn(|r, k| m[(r, cols[k])])
}

/// Singularity test free of the units of rows and columns: with every column scaled to unit
/// norm, |det| / Π ‖row‖ (1 for orthogonal rows, 0 when singular). `det` is the determinant
/// of `e_u` itself (its LU's; None when a pivot vanished): scaling the columns divides it by
/// their norms.
fn conditioning_ratio(e_u: &SMatrix<f64, 5, 5>, det: Option<f64>) -> f64 {
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
fn checked_lu(
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
struct Lu5 {
    /// L below the diagonal (unit diagonal implied), U on and above it.
    lu: SMatrix<f64, 5, 5>,
    /// Row k of the factors is row perm[k] of the matrix.
    perm: [usize; 5],
    /// 1 / U's diagonal: the solves multiply instead of dividing.
    inv_diag: [f64; 5],
    det: f64,
}

impl Lu5 {
    /// None when a pivot is exactly zero (the determinant is then 0).
    fn new(mut m: SMatrix<f64, 5, 5>) -> Option<Lu5> {
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
    fn inverse(&self) -> SMatrix<f64, 5, 5> {
        self.solve(&SMatrix::<f64, 5, 5>::identity())
    }

    /// The rows `first`.. of A⁻¹ (the others zero): the same numbers as those rows of
    /// [`Lu5::inverse`] (the same solves, the back substitution stopped at row `first`,
    /// since it runs from the last row up).
    fn inverse_from(&self, first: usize) -> SMatrix<f64, 5, 5> {
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
    fn solve<const N: usize>(&self, b: &SMatrix<f64, 5, N>) -> SMatrix<f64, 5, N> {
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
fn det5(m: SMatrix<f64, 5, 5>) -> f64 {
    Lu5::new(m).map_or(0.0, |lu| lu.det)
}

/// The closed-form inverse model 24: ψ = γ2 and each rod by eq. 4.6 close every equation
/// already, so Newton would stop before its first step. What it would check is checked here,
/// without its 5 × 5 algebra: the equations' residual, and the conditioning, which for this
/// subsystem fails only when a rod is tangent to its guide's circle (the drive's column of
/// ∂e/∂c vanishes; otherwise the normalised determinant ratio is at least 1/4). None when the
/// residual is above the tolerance (round-off on extreme parameters): Newton then takes over.
fn igm24(p: &Params, x: f64, y: f64) -> Result<Option<Solution>, GeometryError> {
    // the trigonometry once per call, not once per rod and check; ψ = γ2 is guide 2's angle,
    // whose sine and cosine its frame holds already (n = (cos γ2, sin γ2))
    let psi = p[GAMMA2];
    let frames = [guide_frame(p, Guide::G1), guide_frame(p, Guide::G2)];
    let (s, co) = (frames[1].2.y, frames[1].2.x);
    let mut c = Config::zeros();
    c[X] = x;
    c[Y] = y;
    c[PSI] = psi;
    let mut residual: f64 = 0.0;
    for rod in &RODS[..4] {
        let (o, e, n, side) = match rod.guide {
            Guide::G1 => (frames[0].0, frames[0].1, frames[0].2, -1.0),
            Guide::G2 => (frames[1].0, frames[1].1, frames[1].2, 1.0),
        };
        // eq. 4.6, as rod_igm solves it
        let Reach { a, we, disc } = rod_reach(p, rod, (x, y), (s, co), (o, e, n))?;
        let l = p[rod.l];
        if disc == 0.0 {
            // tangent: the drive's column of ∂e/∂c vanishes
            return Err(GeometryError::Singular {
                subsystem: Subsystem::Tcp,
                ratio: 0.0,
            });
        }
        let q = we + rod.k * disc.sqrt() - p[rod.yb];
        // B − A: along the guide k·(B − A)·e = √disc > 0 by construction; across, the
        // carrier must be on the outer side (see in_assembly_mode)
        let ba = o + n * p[rod.xb] + e * (q + p[rod.yb]) - a;
        if !(side * ba.dot(&n) > 0.0) {
            return Err(GeometryError::AssemblyMode { rod: rod.number });
        }
        let f = ba.norm_squared() - l * l;
        if !f.is_finite() {
            return Err(GeometryError::NonFinite);
        }
        residual = residual.max(f.abs());
        c[q_var(rod.actuator)] = q;
    }
    Ok((residual < TOL_MM2).then_some(Solution {
        c,
        iterations: 0,
        residual,
    }))
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

/// The guide frame of `rod` and the side its carrier must be on across the guide (guide 2 to
/// the right, guide 1 to the left: see [`in_assembly_mode`]).
#[inline]
fn rod_frame(frames: &Frames, rod: &Rod) -> (Frame, f64) {
    match rod.guide {
        Guide::G1 => (frames[0], -1.0),
        Guide::G2 => (frames[1], 1.0),
    }
}

/// Centre of the TCP circle of `rod` at drive position q and platform angle (sin, cos):
/// B(q) − R(ψ)·a. B − A at a TCP t is then centre − t.
#[inline]
fn tcp_circle_centre(
    p: &Params,
    frames: &Frames,
    rod: &Rod,
    q: f64,
    (s, c): (f64, f64),
) -> Vector2<f64> {
    let ((o, e, n), _) = rod_frame(frames, rod);
    let (xa, ya) = (p[rod.xa], p[rod.ya]);
    o + n * p[rod.xb] + e * (q + p[rod.yb]) - Vector2::new(c * xa - s * ya, s * xa + c * ya)
}

/// B − A of `rod` in the assembly mode (carrier ahead along the guide by the rod's k, outer
/// side across it), as [`rod_in_assembly_mode`] tests it.
#[inline]
fn assembled(frames: &Frames, rod: &Rod, ba: Vector2<f64>) -> bool {
    let ((_, e, n), side) = rod_frame(frames, rod);
    rod.k * ba.dot(&e) > 0.0 && side * ba.dot(&n) > 0.0
}

/// The TCP where the circles of rods `a` and `b` (drive indexes, at positions qa, qb) meet
/// in the assembly mode of both, at platform angle (sin, cos): annex A, as [`fgm_start`]
/// takes it (the first candidate in both modes). None where the circles do not meet or
/// neither candidate is assembled.
fn two_circles(
    p: &Params,
    frames: &Frames,
    (a, qa): (usize, f64),
    (b, qb): (usize, f64),
    sc: (f64, f64),
) -> Option<Vector2<f64>> {
    let (ra, rb) = (&RODS[a], &RODS[b]);
    let ca = tcp_circle_centre(p, frames, ra, qa, sc);
    let cb = tcp_circle_centre(p, frames, rb, qb, sc);
    let (la, lb) = (p[ra.l], p[rb.l]);
    // in units of the centres' distance d (no root for d): the foot of the chord lies at
    // t·(cb − ca) from ca, the candidates at ±√(h²/d²) across
    let d_vec = cb - ca;
    let inv_d2 = 1.0 / d_vec.norm_squared();
    let t = 0.5 * (la * la - lb * lb) * inv_d2 + 0.5;
    let h2 = la * la * inv_d2 - t * t;
    if !(h2 >= 0.0 && inv_d2.is_finite()) {
        return None;
    }
    let perp = Vector2::new(-d_vec.y, d_vec.x) * h2.sqrt();
    let base = ca + d_vec * t;
    [base + perp, base - perp]
        .into_iter()
        .find(|&tcp| assembled(frames, ra, ca - tcp) && assembled(frames, rb, cb - tcp))
}

/// Drive position q4 of a forward solve: known (b = q4) or rod 4's by eq. 4.6.
#[inline]
fn fgm_q4(
    p: &Params,
    frames: &Frames,
    tcp: Vector2<f64>,
    sc: (f64, f64),
    b: usize,
    qb: f64,
) -> Option<f64> {
    if b == 3 {
        return Some(qb);
    }
    let rod4 = &RODS[3];
    rod_igm_at(p, rod4, tcp.x, tcp.y, sc, rod_frame(frames, rod4).0).ok()
}

/// Rod 5's closure |A − B|² − l² at platform angle (sin, cos) with the TCP on the two known
/// rods' circles and q4 known or from rod 4: the one equation the two-circle solution leaves
/// open in model 29. None where the circles do not meet.
fn rod5_open(
    p: &Params,
    frames: &Frames,
    ka: (usize, f64),
    kb: (usize, f64),
    sc: (f64, f64),
) -> Option<f64> {
    let (_, _, ba) = rod5_at(p, frames, ka, kb, sc)?;
    Some(ba.norm_squared() - p[RODS[4].l] * p[RODS[4].l])
}

/// What [`rod5_open`] builds: the TCP on the two known rods' circles, q4, and rod 5's B − A.
#[inline]
fn rod5_at(
    p: &Params,
    frames: &Frames,
    (a, qa): (usize, f64),
    (b, qb): (usize, f64),
    sc: (f64, f64),
) -> Option<(Vector2<f64>, f64, Vector2<f64>)> {
    let tcp = two_circles(p, frames, (a, qa), (b, qb), sc)?;
    let q4 = fgm_q4(p, frames, tcp, sc, b, qb)?;
    let ba = tcp_circle_centre(p, frames, &RODS[4], q4, sc) - tcp;
    Some((tcp, q4, ba))
}

/// [`rod5_open`] and its derivative in ψ, for the warm Newton step ([`newton_secant_psi`]).
/// Every closure stays closed as ψ moves: rod i's TCP circle centre c_i = B_i(q_i) − R(ψ)·a_i
/// moves by c_i′ = e_i·q_i′ − perp(R(ψ)·a_i); the TCP t stays on the two known rods' circles,
/// (c − t)·(c′ − t′) = 0 for both, a 2 × 2 solve for t′; q4 from rod 4 moves by
/// q4′ = (B4 − A4)·A4′ / (B4 − A4)·e with A4′ = t′ + perp(R(ψ)·a4); and g′ = 2 (B5 − A5)·(c5′ −
/// t′). None where [`rod5_open`] is; a non-finite slope (circles tangent) is the caller's
/// to meet (its step leaves [`WARM_PSI_RAD`]).
fn rod5_open_slope(
    p: &Params,
    frames: &Frames,
    (a, qa): (usize, f64),
    (b, qb): (usize, f64),
    sc: (f64, f64),
) -> Option<(f64, f64)> {
    let (tcp, q4, ba5) = rod5_at(p, frames, (a, qa), (b, qb), sc)?;
    let (rod4, rod5) = (&RODS[3], &RODS[4]);
    // −perp(R(ψ)·a): how a TCP circle's centre moves with ψ at a fixed drive
    let turn = |rod: &Rod| {
        let (xa, ya) = (p[rod.xa], p[rod.ya]);
        let (s, c) = sc;
        Vector2::new(s * xa + c * ya, s * ya - c * xa)
    };
    let ua = tcp_circle_centre(p, frames, &RODS[a], qa, sc) - tcp;
    let ub = tcp_circle_centre(p, frames, &RODS[b], qb, sc) - tcp;
    let (ra, rb) = (ua.dot(&turn(&RODS[a])), ub.dot(&turn(&RODS[b])));
    let dt =
        Vector2::new(ra * ub.y - rb * ua.y, ua.x * rb - ub.x * ra) / (ua.x * ub.y - ua.y * ub.x);
    // rods 4 and 5 share guide 2
    let ((_, e, _), _) = rod_frame(frames, rod5);
    let dq4 = if b == 3 {
        0.0
    } else {
        let ba4 = tcp_circle_centre(p, frames, rod4, q4, sc) - tcp;
        ba4.dot(&(dt - turn(rod4))) / ba4.dot(&e)
    };
    let g = ba5.norm_squared() - p[rod5.l] * p[rod5.l];
    Some((g, 2.0 * ba5.dot(&(e * dq4 + turn(rod5) - dt))))
}

/// ψ closing rod 5's loop for a model-29 forward solve ([`rod5_open`]), by the secant from γ2
/// ([`secant_psi`]) or from a `warm` ψ by a Newton step, then the secant
/// ([`newton_secant_psi`]); with its sine and cosine. None where an iterate leaves the
/// circles' intersection.
fn settled_psi_fgm(
    p: &Params,
    frames: &Frames,
    (ka, kb): ((usize, f64), (usize, f64)),
    warm: Option<f64>,
) -> Option<(f64, (f64, f64))> {
    let g = |sc| rod5_open(p, frames, ka, kb, sc).ok_or(());
    match warm {
        None => secant_psi(p[GAMMA2], (frames[1].2.y, frames[1].2.x), g),
        Some(w) => newton_secant_psi(w, |sc| rod5_open_slope(p, frames, ka, kb, sc).ok_or(()), g),
    }
    .ok()
}

/// Closed-form forward model of the subsystem (qa, qb) (drive indexes a < b < 4): ψ = γ2 for
/// model 24, ψ settled on rod 5's closure by the secant for model 29 ([`settled_psi_fgm`]);
/// the TCP where the two known rods' circles meet, the other drives by eq. 4.6. What Newton
/// and [`solve`] would check is checked in closed form ([`closed_fgm_at`]); None where a
/// check fails: the general solver then decides, with its errors.
fn fgm_closed(
    p: &Params,
    frames: &Frames,
    model: Model,
    (a, qa): (usize, f64),
    (b, qb): (usize, f64),
) -> Option<Solution> {
    let (psi, sc) = match model {
        // ψ = γ2: guide 2's frame holds its sine and cosine (n = (cos γ2, sin γ2))
        Model::M24 => (p[GAMMA2], (frames[1].2.y, frames[1].2.x)),
        Model::M29 => settled_psi_fgm(p, frames, ((a, qa), (b, qb)), None)?,
    };
    closed_fgm_at(p, model, frames, (a, qa), (b, qb), (psi, sc))
}

/// The configuration of the forward solve at platform angle ψ, checked: every equation rod
/// closed (largest residual below [`TOL_MM2`]), in its assembly mode, and the subsystem's
/// conditioning ratio above [`SINGULAR_RATIO`] ([`fgm_ratio_squared`]).
fn closed_fgm_at(
    p: &Params,
    model: Model,
    frames: &Frames,
    (a, qa): (usize, f64),
    (b, qb): (usize, f64),
    (psi, sc): (f64, (f64, f64)),
) -> Option<Solution> {
    let tcp = two_circles(p, frames, (a, qa), (b, qb), sc)?;
    let mut c = Config::zeros();
    (c[X], c[Y], c[PSI]) = (tcp.x, tcp.y, psi);
    // per rod: ∂e/∂(x, y, ψ) and ∂e/∂q
    let mut rows = [[0.0; 4]; 5];
    let mut residual: f64 = 0.0;
    let (s, co) = sc;
    for (i, rod) in equation_rods(model).iter().enumerate() {
        let ((o, e, n), side) = rod_frame(frames, rod);
        let (xa, ya, l) = (p[rod.xa], p[rod.ya], p[rod.l]);
        // R(ψ)·a once per rod: A, and dA/dψ = perp(R(ψ)·a)
        let arm = Vector2::new(co * xa - s * ya, s * xa + co * ya);
        // A − (o + n·xb): eq. 4.6's w, and B − A = e·(q + yb) − w
        let w = tcp + arm - o - n * p[rod.xb];
        let j = rod.actuator;
        let q = if j == a {
            qa
        } else if j == b {
            qb
        } else if i < 4 {
            // eq. 4.6, as rod_igm writes it
            let we = w.dot(&e);
            let disc = we * we - w.norm_squared() + l * l;
            if !(disc >= 0.0) {
                return None;
            }
            we + rod.k * disc.sqrt() - p[rod.yb]
        } else {
            c[q_var(j)]
        };
        c[q_var(j)] = q;
        let ba = e * (q + p[rod.yb]) - w;
        if !(rod.k * ba.dot(&e) > 0.0 && side * ba.dot(&n) > 0.0) {
            return None;
        }
        residual = residual.max((ba.norm_squared() - l * l).abs());
        let da_dpsi = Vector2::new(-arm.y, arm.x);
        rows[i] = [
            -2.0 * ba.x,
            -2.0 * ba.y,
            -2.0 * ba.dot(&da_dpsi),
            2.0 * ba.dot(&e),
        ];
    }
    if !(residual < TOL_MM2)
        || !(fgm_ratio_squared(model, a, b, &rows) > SINGULAR_RATIO * SINGULAR_RATIO)
    {
        return None;
    }
    Some(Solution {
        c,
        iterations: 0,
        residual,
    })
}

/// [`conditioning_ratio`]² of a forward subsystem (drives a < b known) in closed form. The
/// unknowns are (x, y, ψ, q_c, q_d) (the other two drives, in order); rod i's row of ∂e/∂c is
/// g_i = (∂e/∂x, ∂e/∂y, ∂e/∂ψ) and d_i on its own drive (`rows[i]` = (g_i, d_i)); model 24's
/// fifth row is ψ's (0, 0, 1, 0, 0). A drive column with one entry factors out, so
/// - model 24: det = d_c·d_d·(g_a × g_b) (x, y only, the ψ row taking ψ's column),
/// - model 29, q4 known: det = d_c·d_d·det(g_a, g_b, g_5),
/// - model 29, q4 unknown (c the other): det = d_c·det(g_a, g_b, d_4·g_5 − d_5·g_4).
///
/// The ratio then follows from the matrix's column and row norms, squared (no roots); for
/// model 24 written out ([`ratio24_squared`]).
fn fgm_ratio_squared(model: Model, a: usize, b: usize, rows: &[[f64; 4]; 5]) -> f64 {
    // the unknown drives, in order
    let [c, d] = {
        let mut u = [0; 2];
        for (n, j) in (0..4).filter(|&j| j != a && j != b).enumerate() {
            u[n] = j;
        }
        u
    };
    if model == Model::M24 {
        return ratio24_squared([a, b, c, d], rows);
    }
    let g = |i: usize| Vector3::new(rows[i][0], rows[i][1], rows[i][2]);
    let det = if b == 3 {
        rows[c][3] * rows[d][3] * g(a).dot(&g(b).cross(&g(4)))
    } else {
        let w = g(4) * rows[3][3] - g(3) * rows[4][3];
        rows[c][3] * g(a).dot(&g(b).cross(&w))
    };
    // e_u's entries: (g_i, d_i on drive c's column, on drive d's column)
    let mut m = [[0.0; 5]; 5];
    for (i, (row, rod)) in m.iter_mut().zip(&RODS).enumerate() {
        let j = rod.actuator;
        let dq = rows[i][3];
        *row = [
            rows[i][0],
            rows[i][1],
            rows[i][2],
            if j == c { dq } else { 0.0 },
            if j == d { dq } else { 0.0 },
        ];
    }
    ratio_squared(&m, det)
}

/// Model 24's ratio² of [`fgm_ratio_squared`] written out (the drives `[a, b, c, d]`: known,
/// then unknown). With the column sums of squares cx, cy (x, y over rods 1-4), cψ (ψ, with
/// the ψ row's 1) and d_c², d_d², and s_i = gx_i²/cx + gy_i²/cy + A_i²/cψ (+1 for the rows
/// of c and d, whose drive entry scales to 1), det² = d_c²·d_d²·(g_a × g_b)² and the ψ row's
/// norm² 1/cψ cancel: ratio² = (g_a × g_b)² / (cx·cy·s_a·s_b·s_c·s_d). Three divisions
/// instead of the general form's five and its 5 × 5 loops; 0 where a column vanishes.
fn ratio24_squared([a, b, c, d]: [usize; 4], rows: &[[f64; 4]; 5]) -> f64 {
    let sum = |k: usize| rows[..4].iter().map(|r| r[k] * r[k]).sum::<f64>();
    let (cx, cy, cpsi) = (sum(0), sum(1), sum(2) + 1.0);
    if !(cx > 0.0 && cy > 0.0) || rows[c][3] == 0.0 || rows[d][3] == 0.0 {
        return 0.0;
    }
    let (ix, iy, ipsi) = (1.0 / cx, 1.0 / cy, 1.0 / cpsi);
    let s = |i: usize| {
        rows[i][0] * rows[i][0] * ix + rows[i][1] * rows[i][1] * iy + rows[i][2] * rows[i][2] * ipsi
    };
    let cross = rows[a][0] * rows[b][1] - rows[a][1] * rows[b][0];
    cross * cross * ix * iy / (s(a) * s(b) * (s(c) + 1.0) * (s(d) + 1.0))
}

/// [`conditioning_ratio`] squared, from the matrix and its determinant: with every
/// column scaled to unit norm, det² / Π ‖row‖². NaN (which fails every comparison) where the
/// input is not finite.
fn ratio_squared(m: &[[f64; 5]; 5], det: f64) -> f64 {
    let mut col = [0.0; 5];
    for row in m {
        for k in 0..5 {
            col[k] += row[k] * row[k];
        }
    }
    // a zero column leaves the determinant 0; check_conditioning leaves it unscaled
    let inv = col.map(|v| if v > 0.0 { 1.0 / v } else { 1.0 });
    let scale: f64 = col.iter().map(|&v| if v > 0.0 { v } else { 1.0 }).product();
    let norms: f64 = m
        .iter()
        .map(|row| (0..5).map(|k| row[k] * row[k] * inv[k]).sum::<f64>())
        .product();
    det * det / scale / norms
}

/// Solve a geometric model: the configuration that closes every loop given two known
/// variables. `known` holds (x, y) for [`Subsystem::Tcp`] or the two actuator positions.
pub fn solve(
    p: &Params,
    model: Model,
    sub: Subsystem,
    known: [f64; 2],
) -> Result<Solution, GeometryError> {
    if let Subsystem::Actuators(..) = sub {
        // its own finiteness check, closed form, then the general solver
        return fgm_with_frames(p, &frames(p), model, sub, known);
    }
    if !known.iter().all(|v| v.is_finite()) {
        return Err(GeometryError::NonFinite);
    }
    if model == Model::M24 && sub == Subsystem::Tcp {
        if let Some(sol) = igm24(p, known[0], known[1])? {
            return Ok(sol);
        }
    }
    if model == Model::M29 && sub == Subsystem::Tcp {
        if let Some(sol) = igm29(p, known[0], known[1]) {
            return Ok(sol);
        }
    }
    general(p, model, sub, known)
}

/// [`solve`] of a forward subsystem with the guides' frames given: the closed form
/// ([`fgm_closed`]) where its checks pass, else the general solver.
pub(crate) fn fgm_with_frames(
    p: &Params,
    frames: &Frames,
    model: Model,
    sub: Subsystem,
    known: [f64; 2],
) -> Result<Solution, GeometryError> {
    if !known.iter().all(|v| v.is_finite()) {
        return Err(GeometryError::NonFinite);
    }
    if let Subsystem::Actuators(a, b) = sub {
        if a < b && b < 4 {
            if let Some(sol) = fgm_closed(p, frames, model, (a, known[0]), (b, known[1])) {
                return Ok(sol);
            }
        }
    }
    general(p, model, sub, known)
}

/// Largest move of ψ from a warm start that [`fgm29_from`] accepts, rad: the servo stream
/// moves ψ by µrad per sample, the other root of rod 5's closure lies radians away.
const WARM_PSI_RAD: f64 = 1e-3;

/// The model-29 forward model of the subsystem (qa, qb) (drive indexes a < b < 4), its secant
/// in ψ started from `psi_warm` (the previous sample's rigid ψ) instead of γ2: the same
/// configuration as [`fgm_with_frames`] (the same root, settled to the same bound, with the
/// same closed checks), in fewer closures. Where the warm secant fails, a check fails, or ψ
/// settles more than [`WARM_PSI_RAD`] from `psi_warm`, [`fgm_with_frames`] decides.
pub(crate) fn fgm29_from(
    p: &Params,
    frames: &Frames,
    (a, b): (usize, usize),
    known: [f64; 2],
    psi_warm: f64,
) -> Result<Solution, GeometryError> {
    let ka = (a, known[0]);
    let kb = (b, known[1]);
    if a < b && b < 4 && psi_warm.is_finite() && known.iter().all(|v| v.is_finite()) {
        let warm = settled_psi_fgm(p, frames, (ka, kb), Some(psi_warm))
            .filter(|(psi, _)| (psi - psi_warm).abs() <= WARM_PSI_RAD)
            .and_then(|settled| closed_fgm_at(p, Model::M29, frames, ka, kb, settled));
        if let Some(sol) = warm {
            return Ok(sol);
        }
    }
    fgm_with_frames(p, frames, Model::M29, Subsystem::Actuators(a, b), known)
}

/// The general solver: Newton from the analytic start, then the assembly check of every
/// equation rod.
fn general(
    p: &Params,
    model: Model,
    sub: Subsystem,
    known: [f64; 2],
) -> Result<Solution, GeometryError> {
    let start = match sub {
        Subsystem::Tcp if model == Model::M29 => igm29_start(p, known[0], known[1])?,
        Subsystem::Tcp => igm_start(p, known[0], known[1])?,
        Subsystem::Actuators(a, b) => fgm_start(p, a, b, known[0], known[1])?,
    };
    let sol = newton(p, model, sub, start)?;
    let t = Trig::new(p, &sol.c);
    for rod in equation_rods(model) {
        if !rod_in_assembly_mode(p, rod, &sol.c, &t) {
            return Err(GeometryError::AssemblyMode { rod: rod.number });
        }
    }
    Ok(sol)
}

/// Inverse geometric model: actuator positions (and ψ) of the TCP position (x, y).
pub fn igm(p: &Params, model: Model, x: f64, y: f64) -> Result<Solution, GeometryError> {
    solve(p, model, Subsystem::Tcp, [x, y])
}

/// Forward geometric model of the non-redundant subsystem (q1, q4).
pub fn fgm(p: &Params, model: Model, q1: f64, q4: f64) -> Result<Solution, GeometryError> {
    solve(p, model, Subsystem::NR, [q1, q4])
}

/// Redundant geometric model: (q2, q3) from (q1, q4).
pub fn rgm(p: &Params, model: Model, q1: f64, q4: f64) -> Result<[f64; 2], GeometryError> {
    let s = fgm(p, model, q1, q4)?;
    Ok([s.c[q_var(1)], s.c[q_var(2)]])
}

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

#[cfg(test)]
#[expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]
mod tests {
    use super::*;

    /// det5 against nalgebra's LU determinant on random matrices, a singular one, and a
    /// permutation (its sign).
    #[test]
    fn det5_matches_the_lu_determinant() {
        let mut x = 0x2545_f491_4f6c_dd1d_u64;
        for _ in 0..200 {
            let m = SMatrix::<f64, 5, 5>::from_fn(|_, _| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            });
            let (a, b) = (det5(m), m.determinant());
            assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-3), "{a} vs {b}");
        }
        // the solves too: A X = B for 31 right-hand sides, against nalgebra's LU
        for _ in 0..50 {
            let mut next = || {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            };
            let a = SMatrix::<f64, 5, 5>::from_fn(|_, _| next());
            let b = SMatrix::<f64, 5, 31>::from_fn(|_, _| next());
            let ours = Lu5::new(a).expect("regular").solve(&b);
            let want = a.lu().solve(&b).expect("regular");
            assert!(
                (ours - want).amax() <= 1e-10 * want.amax(),
                "{ours} vs {want}"
            );
            assert!((a * ours - b).amax() < 1e-12, "residual");
        }
        let mut singular = SMatrix::<f64, 5, 5>::identity();
        singular.set_row(4, &singular.row(3).clone_owned());
        assert_eq!(det5(singular), 0.0);
        let mut swap = SMatrix::<f64, 5, 5>::identity();
        swap.swap_rows(0, 3);
        assert_eq!(det5(swap), -1.0);
    }

    /// The model-29 igm (the closed checks of [`igm29`], else Newton from the rod-5 start)
    /// gives what Newton from the model-24 start gives (to 1e-9 mm, both within the solver's
    /// tolerance), refuses the poses that refuses, and needs the general solver nowhere in
    /// the workspace.
    #[test]
    fn igm29_start_converges_to_the_same_pose() {
        let mut p = Params::nominal();
        for (k, i) in [0, 3, 7, 12, 20, 24, 26].into_iter().enumerate() {
            p[i] += 0.05 * (k as f64 + 1.0);
        }
        let (mut solved, mut closed, mut steps_old, mut steps_new) = (0, 0, 0, 0);
        for i in 0..31 {
            for j in 0..31 {
                let (x, y) = (-300.0 + 20.0 * f64::from(i), 500.0 + 80.0 * f64::from(j));
                let new = solve(&p, Model::M29, Subsystem::Tcp, [x, y]);
                let old = igm_start(&p, x, y)
                    .and_then(|c| newton(&p, Model::M29, Subsystem::Tcp, c))
                    .and_then(|sol| {
                        let t = Trig::new(&p, &sol.c);
                        match RODS
                            .iter()
                            .find(|r| !rod_in_assembly_mode(&p, r, &sol.c, &t))
                        {
                            Some(rod) => Err(GeometryError::AssemblyMode { rod: rod.number }),
                            None => Ok(sol),
                        }
                    });
                match (new, old) {
                    (Ok(a), Ok(b)) => {
                        let gap = (a.c - b.c).amax();
                        assert!(gap < 1e-9, "({x}, {y}): {gap:e}");
                        solved += 1;
                        closed += usize::from(igm29(&p, x, y).is_some());
                        steps_new += a.iterations;
                        steps_old += b.iterations;
                    }
                    (Err(_), Err(_)) => {}
                    (a, b) => panic!("({x}, {y}): rod-5 start {a:?}, model-24 start {b:?}"),
                }
            }
        }
        assert!(solved > 500, "only {solved} poses solved");
        assert_eq!(closed, solved, "poses left to the general solver");
        assert!(
            steps_new < steps_old,
            "Newton steps {steps_new} vs {steps_old}"
        );
    }

    /// The closed-form model-24 igm gives what the general solver gives (Newton from the same
    /// start), over the workspace and beyond it, on a machine with parameter errors; and
    /// refuses the same poses.
    #[test]
    fn closed_form_igm24_matches_the_general_solver() {
        let mut p = Params::nominal();
        for (k, i) in [0, 3, 7, 12, 20].into_iter().enumerate() {
            p[i] += 0.05 * (k as f64 + 1.0);
        }
        let mut solved = 0;
        for i in 0..41 {
            for j in 0..41 {
                let (x, y) = (-400.0 + 20.0 * f64::from(i), 300.0 + 70.0 * f64::from(j));
                let fast = igm24(&p, x, y);
                let general = igm_start(&p, x, y)
                    .and_then(|c| newton(&p, Model::M24, Subsystem::Tcp, c))
                    .and_then(|sol| {
                        for rod in &RODS[..4] {
                            let tcp = Vector2::new(x, y);
                            if !in_assembly_mode(
                                &p,
                                rod,
                                tcp,
                                sol.c[PSI],
                                sol.c[q_var(rod.actuator)],
                            ) {
                                return Err(GeometryError::AssemblyMode { rod: rod.number });
                            }
                        }
                        Ok(sol)
                    });
                match (fast, general) {
                    (Ok(Some(f)), Ok(g)) => {
                        assert_eq!(f.c, g.c, "({x}, {y})");
                        solved += 1;
                    }
                    (Err(_), Err(_)) => {}
                    (f, g) => panic!("({x}, {y}): closed form {f:?}, general {g:?}"),
                }
            }
        }
        assert!(solved > 500, "only {solved} poses solved");
    }

    /// Parameters with uniform random errors within ±0.1 mm and ±2e-4 rad (the twin's spread).
    fn perturbed(seed: u64) -> Params {
        let mut x = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut p = Params::nominal();
        for i in 0..N_PARAMS {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let u = 2.0 * ((x >> 11) as f64 / (1u64 << 53) as f64) - 1.0;
            p[i] += u * match crate::params::unit(i) {
                crate::params::Unit::Mm => 0.1,
                crate::params::Unit::Rad => 2e-4,
            };
        }
        p
    }

    /// The general forward solver alone: Newton from the model-24 start, then the assembly
    /// check of every equation rod (what [`solve`] did before the closed forms).
    fn general_fgm(
        p: &Params,
        model: Model,
        sub: Subsystem,
        k: [f64; 2],
    ) -> Result<Solution, GeometryError> {
        let Subsystem::Actuators(a, b) = sub else {
            unreachable!("forward subsystems only")
        };
        let sol = newton(p, model, sub, fgm_start(p, a, b, k[0], k[1])?)?;
        let t = Trig::new(p, &sol.c);
        match equation_rods(model)
            .iter()
            .find(|r| !rod_in_assembly_mode(p, r, &sol.c, &t))
        {
            Some(rod) => Err(GeometryError::AssemblyMode { rod: rod.number }),
            None => Ok(sol),
        }
    }

    /// The closed-form forward models ([`fgm_closed`]) of both models and every viable
    /// subsystem give what the general solver gives (to 1e-9 mm), close every loop, and
    /// return the pose the igm started from (the independent truth of a round trip), over a
    /// 25 × 25 grid through the workspace on three machines with random parameter errors; no
    /// pose the general solver solves is left to it.
    #[test]
    fn closed_form_fgm_matches_the_general_solver() {
        for seed in 1..=3 {
            let p = perturbed(seed);
            for model in [Model::M24, Model::M29] {
                for sub in Subsystem::VIABLE {
                    let Subsystem::Actuators(a, b) = sub else {
                        unreachable!("forward subsystems only")
                    };
                    let mut solved = 0;
                    for i in 0..25 {
                        for j in 0..25 {
                            let (x, y) =
                                (-300.0 + 25.0 * f64::from(i), 700.0 + 70.0 * f64::from(j));
                            let Ok(pose) = igm(&p, model, x, y) else {
                                continue;
                            };
                            let k = [pose.c[q_var(a)], pose.c[q_var(b)]];
                            let fast = fgm_closed(&p, &frames(&p), model, (a, k[0]), (b, k[1]));
                            match (fast, general_fgm(&p, model, sub, k)) {
                                (Some(f), Ok(g)) => {
                                    let gap = (f.c - g.c).amax();
                                    assert!(gap < 1e-9, "{model} {sub} ({x}, {y}): {gap:e}");
                                    let back = (f.c - pose.c).amax();
                                    assert!(
                                        back < 1e-9,
                                        "{model} {sub} ({x}, {y}): round trip {back:e}"
                                    );
                                    let e = closure(&p, model, &f.c).e.amax();
                                    assert!(
                                        e < TOL_MM2,
                                        "{model} {sub} ({x}, {y}): residual {e:e}"
                                    );
                                    assert_eq!(solve(&p, model, sub, k).unwrap().c, f.c);
                                    solved += 1;
                                }
                                (f, g) => panic!(
                                    "{model} {sub} ({x}, {y}): closed form {f:?}, general {g:?}"
                                ),
                            }
                        }
                    }
                    assert!(solved > 400, "{model} {sub}: only {solved} poses solved");
                }
            }
        }
    }

    /// The sensitivities of chosen rows ([`sensitivity_rows_into`], what a calibration row
    /// reads) are [`sensitivity_into`]'s rows to the bit, for known and unknown variables of
    /// every viable forward subsystem and both models, and leave the other rows untouched;
    /// and the full sensitivities predict how the solved configuration moves when a
    /// parameter does (central differences of the solver itself, an independent truth).
    #[test]
    fn chosen_sensitivity_rows_are_the_full_rows_to_the_bit() {
        let p = perturbed(2);
        let mut checked = 0;
        for model in [Model::M24, Model::M29] {
            for sub in Subsystem::VIABLE {
                let Subsystem::Actuators(a, b) = sub else {
                    unreachable!("forward subsystems only")
                };
                for (x, y) in [(-200.0, 900.0), (0.0, 1400.0), (150.0, 2000.0)] {
                    let Ok(pose) = igm(&p, model, x, y) else {
                        continue;
                    };
                    let k = [pose.c[q_var(a)], pose.c[q_var(b)]];
                    let sol = solve(&p, model, sub, k).expect("fgm of an igm pose");
                    let full = sensitivity(&p, model, sub, &sol).expect("regular");
                    let vars = [q_var(1), q_var(2), q_var(a)];
                    let mut rows = Sensitivity::zeros();
                    rows.dc_dp.fill(7.0);
                    sensitivity_rows_into(&p, model, (sub, &sol), &frames(&p), &vars, &mut rows)
                        .expect("regular");
                    for v in 0..7 {
                        let (want, got) = (full.dc_dp.row(v), rows.dc_dp.row(v));
                        if vars.contains(&v) {
                            let bits =
                                |r: &[f64]| r.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                            assert_eq!(
                                bits(want.clone_owned().as_slice()),
                                bits(got.clone_owned().as_slice())
                            );
                            assert_eq!(full.dc_dk.row(v), rows.dc_dk.row(v));
                        } else {
                            assert!(got.iter().all(|&e| e == 7.0), "row {v} written");
                        }
                    }
                    // d q2 / d l1 against the solver's central difference
                    let h = 1e-6;
                    let (mut up, mut down) = (p, p);
                    up[crate::params::L1] += h;
                    down[crate::params::L1] -= h;
                    let moved = |p: &Params| solve(p, model, sub, k).expect("near").c[q_var(1)];
                    let fd = (moved(&up) - moved(&down)) / (2.0 * h);
                    let an = full.dc_dp[(q_var(1), crate::params::L1)];
                    assert!((fd - an).abs() < 1e-5 * (1.0 + an.abs()), "{fd} vs {an}");
                    checked += 1;
                }
            }
        }
        assert!(checked >= 12, "only {checked} poses checked");
    }

    /// Where the closed form refuses (actuator positions no pose of the machine reaches, or
    /// the singular subsystems), [`solve`] answers with the general solver's typed error.
    #[test]
    fn closed_form_fgm_refusals_keep_the_typed_errors() {
        let p = perturbed(4);
        for model in [Model::M24, Model::M29] {
            let q = igm(&p, model, 0.0, 1700.0).unwrap().q();
            for sub in Subsystem::VIABLE {
                let Subsystem::Actuators(a, b) = sub else {
                    unreachable!("forward subsystems only")
                };
                // the two carriers 3 m apart: the rods cannot meet
                let k = [q[a] - 1500.0, q[b] + 1500.0];
                assert!(fgm_closed(&p, &frames(&p), model, (a, k[0]), (b, k[1])).is_none());
                assert_eq!(solve(&p, model, sub, k), general_fgm(&p, model, sub, k));
                assert!(solve(&p, model, sub, k).is_err(), "{model} {sub}");
            }
            // the singular pairs: solved alike where regular, refused alike where not
            for (a, b) in [(1, 3), (0, 2)] {
                let sub = Subsystem::Actuators(a, b);
                for x in [-200.0, 0.0, 200.0] {
                    let q = igm(&p, model, x, 1500.0).unwrap().q();
                    match (
                        solve(&p, model, sub, [q[a], q[b]]),
                        general_fgm(&p, model, sub, [q[a], q[b]]),
                    ) {
                        (Ok(f), Ok(g)) => assert!((f.c - g.c).amax() < 1e-9, "{model} {sub}"),
                        (Err(f), Err(g)) => assert_eq!(
                            std::mem::discriminant(&f),
                            std::mem::discriminant(&g),
                            "{model} {sub}: {f:?} vs {g:?}"
                        ),
                        (f, g) => panic!("{model} {sub}: {f:?} vs {g:?}"),
                    }
                }
            }
            let nan = solve(&p, model, Subsystem::NR, [f64::NAN, 1.0]);
            assert_eq!(nan, Err(GeometryError::NonFinite));
        }
    }

    /// The closed-form conditioning of the forward subsystems ([`fgm_ratio_squared`]) is the
    /// general one ([`conditioning_ratio`] on the LU's determinant) to 1e-9 relative, for
    /// both models and every pair of drives, the singular pairs (q2, q4) and (q1, q3) near
    /// x = 0 included.
    #[test]
    fn closed_form_fgm_conditioning_is_the_general_ratio() {
        let p = perturbed(5);
        for model in [Model::M24, Model::M29] {
            for (a, b) in [(0, 3), (2, 3), (1, 2), (0, 1), (1, 3), (0, 2)] {
                let sub = Subsystem::Actuators(a, b);
                for (x, y) in [
                    (0.0, 1700.0),
                    (0.01, 1000.0),
                    (-250.0, 900.0),
                    (300.0, 2200.0),
                ] {
                    let sol = igm(&p, model, x, y).unwrap();
                    let cl = closure(&p, model, &sol.c);
                    let e_u = select_columns(&cl.e_c, &sub.unknown());
                    let general = conditioning_ratio(&e_u, Lu5::new(e_u).map(|l| l.det));
                    let rows = std::array::from_fn(|i| {
                        let j = q_var(RODS[i].actuator);
                        [
                            cl.e_c[(i, X)],
                            cl.e_c[(i, Y)],
                            cl.e_c[(i, PSI)],
                            cl.e_c[(i, j)],
                        ]
                    });
                    let closed = fgm_ratio_squared(model, a, b, &rows).sqrt();
                    assert!(
                        (closed - general).abs() <= 1e-9 * general.max(1e-6),
                        "{model} {sub} ({x}, {y}): {closed:e} vs {general:e}"
                    );
                }
            }
        }
    }

    #[test]
    fn spec_check_values() {
        let p = Params::nominal();
        for model in [Model::M24, Model::M29] {
            let s = igm(&p, model, 0.0, 1700.0).expect("igm");
            let q = s.q();
            let want = [2611.0556, 2611.0556, 788.9444, 788.9444];
            for i in 0..4 {
                assert!(
                    (q[i] - want[i]).abs() < 1e-4,
                    "{model} q{} = {}",
                    i + 1,
                    q[i]
                );
            }
            assert!(s.psi().abs() < 1e-12);
        }
    }

    /// The model-29 forward model with its secant warm-started from the previous sample's ψ
    /// ([`fgm29_from`], the elastic checks' rigid reference) is the pose of the one from γ2
    /// (to 1e-9 mm and rad), over a servo-like trajectory (a 100 mm circle in 2,000 samples,
    /// and a 600 mm diagonal in 10 jumps, both carried from sample to sample) on three
    /// machines with random parameter errors, for every viable subsystem; a wild warm ψ
    /// (0.5 rad off) falls back to the same pose too.
    #[test]
    fn warm_rigid_psi_gives_the_pose_from_gamma2() {
        let circle = (0..2000).map(|i| {
            let t = f64::from(i) / 2000.0 * std::f64::consts::TAU;
            (100.0 * t.cos(), 1700.0 + 100.0 * t.sin())
        });
        let diagonal = (0..10).map(|i| (-300.0 + 60.0 * f64::from(i), 900.0 + 80.0 * f64::from(i)));
        let path: Vec<(f64, f64)> = circle.chain(diagonal).collect();
        for seed in 1..=3 {
            let p = perturbed(seed);
            let fr = frames(&p);
            for sub in Subsystem::VIABLE {
                let Subsystem::Actuators(a, b) = sub else {
                    unreachable!("forward subsystems only")
                };
                let mut warm: Option<f64> = None;
                for &(x, y) in &path {
                    let q = igm(&p, Model::M29, x, y).expect("igm").q();
                    let known = [q[a], q[b]];
                    let cold = fgm_with_frames(&p, &fr, Model::M29, sub, known).expect("fgm");
                    // the warm secant itself settles where the closed form from γ2 does
                    if let Some(w) = warm {
                        let ks = ((a, known[0]), (b, known[1]));
                        let closed = fgm_closed(&p, &fr, Model::M29, ks.0, ks.1).is_some();
                        let settled = settled_psi_fgm(&p, &fr, ks, Some(w))
                            .is_some_and(|(psi, _)| (psi - w).abs() <= WARM_PSI_RAD);
                        assert!(settled || !closed, "seed {seed} {sub} ({x}, {y})");
                    }
                    for start in [warm.unwrap_or(p[GAMMA2]), cold.c[PSI] + 0.5] {
                        let hot = fgm29_from(&p, &fr, (a, b), known, start).expect("warm fgm");
                        let gap = (hot.c - cold.c).amax();
                        assert!(gap < 1e-9, "seed {seed} {sub} ({x}, {y}): {gap:e}");
                    }
                    warm = Some(cold.c[PSI]);
                }
            }
        }
    }

    /// The slope of rod 5's closure that the warm Newton step takes ([`rod5_open_slope`]) is
    /// the closure's derivative in ψ: against central differences (h = 1e-6 rad, whose error
    /// h²·g‴/6 and round-off are below 1e-7 of the slope's 6e5 mm²/rad), for every viable
    /// subsystem (q4 known and from rod 4), at the settled ψ and 1 mrad either side, on three
    /// machines with parameter errors.
    #[test]
    fn rod5_slope_is_the_closure_derivative() {
        let h = 1e-6;
        let mut compared = 0;
        for seed in 1..=3 {
            let p = perturbed(seed);
            let fr = frames(&p);
            for (x, y) in [(0.0, 1700.0), (-250.0, 1000.0), (300.0, 2300.0)] {
                let c = igm(&p, Model::M29, x, y).expect("igm").c;
                for sub in Subsystem::VIABLE {
                    let Subsystem::Actuators(a, b) = sub else {
                        unreachable!("forward subsystems only")
                    };
                    let (ka, kb) = ((a, c[q_var(a)]), (b, c[q_var(b)]));
                    for psi in [c[PSI] - 1e-3, c[PSI], c[PSI] + 1e-3] {
                        let g = |v: f64| rod5_open(&p, &fr, ka, kb, v.sin_cos()).expect("open");
                        let (g0, slope) =
                            rod5_open_slope(&p, &fr, ka, kb, psi.sin_cos()).expect("slope");
                        let numeric = (g(psi + h) - g(psi - h)) / (2.0 * h);
                        assert!((g0 - g(psi)).abs() <= 1e-9 * g0.abs().max(1.0));
                        let gap = (slope - numeric).abs();
                        assert!(
                            gap <= 1e-7 * slope.abs(),
                            "seed {seed} {sub} ({x}, {y}) ψ {psi}: {slope:e} vs {numeric:e}"
                        );
                        compared += 1;
                    }
                }
            }
        }
        assert_eq!(compared, 108);
    }

    #[test]
    fn q2_q4_subsystem_is_singular_at_x0() {
        let p = Params::nominal();
        let s = igm(&p, Model::M24, 0.0, 1700.0).expect("igm");
        let q = s.q();
        let r = solve(&p, Model::M24, Subsystem::Actuators(1, 3), [q[1], q[3]]);
        assert!(
            matches!(
                r,
                Err(GeometryError::Singular { .. } | GeometryError::NoIntersection { .. })
            ),
            "{r:?}"
        );
    }
}
