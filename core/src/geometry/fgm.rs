//! The forward model's analytic starts: two circles per known drive pair, and rod 5's closure
//! in model 29.

use super::closure::{
    carrier_joint, equation_rods, platform_joint, rod_residual, Frame, Frames, Trig,
};
use super::config::{q_var, Config, GeometryError, Solution, PSI, SINGULAR_RATIO, TOL_MM2, X, Y};
use super::igm::{newton_secant_psi, rod_igm, rod_igm_at, secant_psi};
use crate::params::{Guide, Model, Params, Rod, GAMMA2, RODS};
use nalgebra::{Vector2, Vector3};

/// Analytic model-24 start for a forward model: intersection of the two rods' circles
/// (annex A) with ψ = γ2, keeping the assembly mode, then the other actuators by eq. 4.6.
pub(super) fn fgm_start(
    p: &Params,
    a: usize,
    b: usize,
    qa: f64,
    qb: f64,
) -> Result<Config, GeometryError> {
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
pub(super) fn in_assembly_mode(p: &Params, rod: &Rod, tcp: Vector2<f64>, psi: f64, q: f64) -> bool {
    let mut c = Config::zeros();
    (c[X], c[Y], c[PSI], c[q_var(rod.actuator)]) = (tcp.x, tcp.y, psi, q);
    rod_in_assembly_mode(p, rod, &c, &Trig::new(p, &c))
}

/// [`in_assembly_mode`] of `rod` in configuration `c`, with its trigonometry given.
pub(super) fn rod_in_assembly_mode(p: &Params, rod: &Rod, c: &Config, t: &Trig) -> bool {
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
pub(super) fn rod5_open(
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
pub(super) fn rod5_open_slope(
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
pub(super) fn settled_psi_fgm(
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
pub(super) fn fgm_closed(
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
pub(super) fn closed_fgm_at(
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
pub(super) fn fgm_ratio_squared(model: Model, a: usize, b: usize, rows: &[[f64; 4]; 5]) -> f64 {
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
