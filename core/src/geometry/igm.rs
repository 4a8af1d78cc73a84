//! The inverse model: each rod by eq. 4.6, the closed-form model 24, and model 29's platform
//! angle by secant steps.

use super::closure::{guide_frame, Trig};
use super::config::{
    q_var, Config, GeometryError, Solution, Subsystem, PSI, SINGULAR_RATIO, TOL_MM2, X, Y,
};
use crate::params::{Guide, Params, Rod, GAMMA2, RODS};
use nalgebra::Vector2;

/// Actuator position of one rod for a platform pose (seed eq. 4.6 with the assembly mode k).
pub fn rod_igm(p: &Params, rod: &Rod, x: f64, y: f64, psi: f64) -> Result<f64, GeometryError> {
    rod_igm_at(p, rod, x, y, psi.sin_cos(), guide_frame(p, rod.guide))
}

/// [`rod_igm`] with sin and cos of ψ and the rod's guide frame given (computed once by a
/// caller that needs them for several rods or several calls).
pub(super) fn rod_igm_at(
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
pub(super) fn igm_start(p: &Params, x: f64, y: f64) -> Result<Config, GeometryError> {
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
pub(super) fn igm29_start(p: &Params, x: f64, y: f64) -> Result<Config, GeometryError> {
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
pub(super) fn secant_psi<E>(
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
pub(super) fn newton_secant_psi<E>(
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
pub(super) fn igm29(p: &Params, x: f64, y: f64) -> Option<Solution> {
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

/// The closed-form inverse model 24: ψ = γ2 and each rod by eq. 4.6 close every equation
/// already, so Newton would stop before its first step. What it would check is checked here,
/// without its 5 × 5 algebra: the equations' residual, and the conditioning, which for this
/// subsystem fails only when a rod is tangent to its guide's circle (the drive's column of
/// ∂e/∂c vanishes; otherwise the normalised determinant ratio is at least 1/4). None when the
/// residual is above the tolerance (round-off on extreme parameters): Newton then takes over.
pub(super) fn igm24(p: &Params, x: f64, y: f64) -> Result<Option<Solution>, GeometryError> {
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

/// Largest move of ψ from a warm start that [`fgm29_from`] accepts, rad: the servo stream
/// moves ψ by µrad per sample, the other root of rod 5's closure lies radians away.
pub(super) const WARM_PSI_RAD: f64 = 1e-3;
