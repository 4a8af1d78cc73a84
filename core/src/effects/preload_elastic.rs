//! `preload_elastic`: the elasto-geometric model with the measured drive forces (the thesis's
//! third approach, 4.5). With all four drives position-controlled, a geometric error turns
//! into internal preload and the rods stretch; the geometric model then sees rods of length
//! l + T/k. From the drive forces f1..f4 recorded at each pose the rod forces T follow from the
//! carriers' and the platform's static balance (7 equations, 5 rod forces, least squares), and
//! the effect's one parameter, the compliance factor c (1 = the default rod stiffness of
//! [`crate::elastic::DEFAULT_ROD_STIFFNESS_N_PER_MM`]), scales the stretch: dl = c · T / k.
//! The stiffness is identified with the geometry.

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable};
use crate::campaign::Campaign;
use crate::elastic::DEFAULT_ROD_STIFFNESS_N_PER_MM;
use crate::geometry::{self, carrier_joint, guide_frame, platform_joint};
use crate::params::{Model, Params, Row, GAMMA1, GAMMA2, N_PARAMS, RODS};
use nalgebra::{SMatrix, SVector};

/// Lever that turns the platform's moment balance (N·mm) into N, so its row weighs like the
/// force rows: about the platform's joint spacing.
const MOMENT_ARM_MM: f64 = 100.0;

/// See the module documentation.
pub struct PreloadElastic;

impl Effect for PreloadElastic {
    fn name(&self) -> &'static str {
        "preload_elastic"
    }
    fn summary(&self) -> &'static str {
        "elastic deformation under internal preload, from the measured drive forces"
    }
    fn covariates(&self) -> &'static [&'static str] {
        &["f1", "f2", "f3", "f4"]
    }
    fn bind(&self, campaign: &Campaign, p: &Params) -> Result<Box<dyn Bound>, NotApplicable> {
        self.bind_among(campaign, p, &[])
    }
    /// The rod forces of each pose balanced on the geometry the model gives it: `p` changed by
    /// the other effects' `moved` parameters, the carriers at the encoder readings changed by
    /// their `moved` positions.
    fn bind_among(
        &self,
        campaign: &Campaign,
        p: &Params,
        moved: &[Delta],
    ) -> Result<Box<dyn Bound>, NotApplicable> {
        let mut stretch = Vec::with_capacity(campaign.poses.len());
        let mut slope = Vec::with_capacity(campaign.poses.len());
        let mut loaded = 0;
        let mut first_force_row = None;
        for (i, pose) in campaign.poses.iter().enumerate() {
            let active = pose.follower.iter().all(|f| !f) && pose.f.iter().any(|f| *f != 0.0);
            if !active || pose.instrument == crate::campaign::Instrument::None {
                // a force row's elastic model stretches the rods by its own forces already:
                // the effect corrects the instrument rows of loaded poses only
                if active {
                    first_force_row.get_or_insert(pose.line);
                }
                stretch.push([0.0; 5]);
                slope.push([Row::zeros(); 5]);
                continue;
            }
            loaded += 1;
            let (p, q) = moved.get(i).map_or((*p, pose.q), |d| d.applied(p, &pose.q));
            let not_applicable = |reason: String| NotApplicable {
                effect: "preload_elastic".into(),
                reason: format!("{}:{}: {reason}", campaign.source, pose.line),
            };
            let t = rod_forces(&p, &q, &pose.f).map_err(not_applicable)?;
            slope.push(stretch_slope(&p, &q, &pose.f, &t).map_err(not_applicable)?);
            stretch.push(t.map(|t| t / DEFAULT_ROD_STIFFNESS_N_PER_MM));
        }
        if loaded == 0 {
            return Err(NotApplicable {
                effect: "preload_elastic".into(),
                reason: match first_force_row {
                    Some(line) => format!(
                        "{}:{line}: only drive-force rows (instrument none) are loaded: their \
                         elastic model stretches the rods by the forces already, the effect \
                         would have no instrument row to correct (stiffness_factor is the force \
                         rows' stiffness unknown)",
                        campaign.source
                    ),
                    None => "no instrument pose with all four drives active and drive forces \
                             recorded"
                        .to_owned(),
                },
            });
        }
        Ok(Box::new(BoundPreload {
            // a rod cannot be stiffer than rigid: a negative compliance absorbs something else
            params: vec![EffectParam::new("compliance", "x default", 1.0).within(0.0, 10.0)],
            at: *p,
            stretch,
            slope,
        }))
    }
}

/// Passes of the balance at the deformed pose: the first at the rigid pose, then at the pose
/// of the rods stretched by the last pass's forces.
const DEFORMED_PASSES: usize = 3;

/// Rod forces (N, tension positive) that balance the recorded drive forces at the pose the
/// loaded machine takes: under a preload of kN the rods stretch by up to a few tenths of a
/// millimetre and the platform turns by 1e-4 rad, which changes the rods' directions against
/// the guides and the arms of the moment balance; balanced at the rigid pose instead, the
/// forces of the parallelogram rods came out 0.3-0.5 % wrong (up to 1 µm of stretch on a
/// stressed twin, against a stretch the instrument rows determine to 0.03 %). The deformed
/// pose is the rigid model's with the rods lengthened by T / k (the default stiffness: a
/// compliance c ≠ 1 moves it by (c − 1) of a second-order term).
fn rod_forces(p: &Params, q: &[f64; 4], f: &[f64; 4]) -> Result<[f64; 5], String> {
    let mut t = balance_at(p, q, f)?;
    for _ in 1..DEFORMED_PASSES {
        let mut stretched = *p;
        for (rod, ti) in RODS.iter().zip(t) {
            stretched[rod.l] += ti / DEFAULT_ROD_STIFFNESS_N_PER_MM;
        }
        t = balance_at(&stretched, q, f)?;
    }
    Ok(t)
}

/// Steps of the slope's differences: a micrometre of a length, a microradian of a guide's
/// angle. The balance is smooth over millimetres: the step's curvature error is 1e-6 of
/// the slope, its round-off 1e-9 of it.
const SLOPE_STEP_MM: f64 = 1e-3;
const SLOPE_STEP_RAD: f64 = 1e-6;

/// ∂(stretch)/∂p of each rod at the default stiffness (mm per parameter unit), the forces
/// `t` balanced at `p`: forward differences of the whole balance, its passes at the
/// deformed pose included (differentiated at the last pass alone, the slope of a
/// parallelogram rod came out 0.14 % short, and a row's, a difference of rods, 2 %).
fn stretch_slope(p: &Params, q: &[f64; 4], f: &[f64; 4], t: &[f64; 5]) -> Result<[Row; 5], String> {
    let mut slope = [Row::zeros(); 5];
    for j in 0..N_PARAMS {
        let h = if j == GAMMA1 || j == GAMMA2 {
            SLOPE_STEP_RAD
        } else {
            SLOPE_STEP_MM
        };
        let mut moved = *p;
        moved[j] += h;
        let tj = rod_forces(&moved, q, f)?;
        for (r, s) in slope.iter_mut().enumerate() {
            s[j] = (tj[r] - t[r]) / h / DEFAULT_ROD_STIFFNESS_N_PER_MM;
        }
    }
    Ok(slope)
}

/// Rod forces that balance the drive forces `f` at the rigid pose of the carriers' (q1, q4)
/// under the parameters `p`: 4 carrier and 3 platform equations, least squares.
fn balance_at(p: &Params, q: &[f64; 4], f: &[f64; 4]) -> Result<[f64; 5], String> {
    let sol = geometry::fgm(p, Model::M29, q[0], q[3]).map_err(|e| format!("rigid pose: {e}"))?;
    let (x, y, psi) = (sol.x(), sol.y(), sol.psi());
    let mut a = SMatrix::<f64, 7, 5>::zeros();
    let mut b = SVector::<f64, 7>::zeros();
    for (i, rod) in RODS.iter().enumerate() {
        let pa = platform_joint(p, rod, x, y, psi);
        let pb = carrier_joint(p, rod, sol.q()[rod.actuator]);
        let u = (pa - pb).normalize();
        let (_, e, _) = guide_frame(p, rod.guide);
        // carrier balance: drive force = Σ T (−u·e) (elastic::spring's convention)
        a[(rod.actuator, i)] = -u.dot(&e);
        // platform balance: Σ −T u = 0 and Σ arm × (−T u) = 0
        let arm = pa - nalgebra::Vector2::new(x, y);
        a[(4, i)] = -u.x;
        a[(5, i)] = -u.y;
        a[(6, i)] = -(arm.x * u.y - arm.y * u.x) / MOMENT_ARM_MM;
    }
    for j in 0..4 {
        b[j] = f[j];
    }
    let n = a.transpose() * a;
    let t = n
        .cholesky()
        .ok_or("the rod forces are not determined by the drive forces at this pose")?
        .solve(&(a.transpose() * b));
    Ok([t[0], t[1], t[2], t[3], t[4]])
}

struct BoundPreload {
    params: Vec<EffectParam>,
    /// The parameters the forces were balanced at.
    at: Params,
    /// Rod stretch at the default stiffness, mm, per pose, ...
    stretch: Vec<[f64; 5]>,
    /// ... and its slope over the parameters at `at` (zero where the pose is not loaded).
    slope: Vec<[Row; 5]>,
}

impl Bound for BoundPreload {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    /// The rod forces balance the drive forces through the rods' directions at the pose:
    /// 0.1 mm of parameter error turns them by 1e-4, their 1-10 kN by 0.3 %, a third of a
    /// micrometre of stretch on rods the instrument rows measure to a few hundredths.
    fn rebinds_from(&self) -> Option<&dyn Effect> {
        Some(&PreloadElastic)
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        for (i, rod) in RODS.iter().enumerate() {
            let s = self.stretch[pose][i];
            value.dp[rod.l] += theta[0] * s;
            partials[0].dp[rod.l] += s;
        }
    }
    /// The stretch at `p` to first order from where the forces were balanced.
    fn correct_at(
        &self,
        pose: usize,
        theta: &[f64],
        p: &Params,
        value: &mut Delta,
        partials: &mut [Delta],
        slopes: &mut Vec<(usize, Row)>,
    ) {
        let dp = Row::from_fn(|j, _| p[j] - self.at[j]);
        for (i, rod) in RODS.iter().enumerate() {
            let g = &self.slope[pose][i];
            if g.iter().all(|v| *v == 0.0) {
                continue;
            }
            let s = self.stretch[pose][i] + g.dot(&dp);
            value.dp[rod.l] += theta[0] * s;
            partials[0].dp[rod.l] += s;
            slopes.push((rod.l, theta[0] * g));
        }
    }
}
