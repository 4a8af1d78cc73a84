//! `preload_elastic`: the elasto-geometric model with the measured drive forces (the thesis's
//! third approach, 4.5). With all four drives position-controlled, a geometric error turns
//! into internal preload and the rods stretch; the geometric model then sees rods of length
//! l + T/k. From the drive forces f1..f4 recorded at each pose the rod forces T follow from the
//! carriers' and the platform's static balance (7 equations, 5 rod forces, least squares), and
//! the effect's one parameter, the compliance factor c (1 = the default rod stiffness of
//! [`crate::elastic::DEFAULT_ROD_STIFFNESS_N_PER_MM`]), scales the stretch: dl = c · T / k.
//! The stiffness is identified with the geometry.
//!
//! A rod of another stiffness than the others (its section, a joint's play, a carrier's
//! guide) stretches by another share: `preload_elastic:rod2` gives rod 2 a compliance of its
//! own beside the others' common one. These are the effect's refinements: the diagnosis
//! keeps one only where the data need it (`diagnose::search::settle`).

use super::effect::{Bound, Delta, Effect, EffectParam, NotApplicable, Slope};
use crate::campaign::Campaign;
use crate::elastic::DEFAULT_ROD_STIFFNESS_N_PER_MM;
use crate::geometry::{self, carrier_joint, guide_frame, platform_joint};
use crate::params::{Model, Params, Row, GAMMA1, GAMMA2, N_PARAMS, RODS};
use nalgebra::{SMatrix, SVector};

/// Lever that turns the platform's moment balance (N·mm) into N, so its row weighs like the
/// force rows: about the platform's joint spacing.
const MOMENT_ARM_MM: f64 = 100.0;

/// See the module documentation.
#[derive(Clone, Debug)]
pub struct PreloadElastic {
    /// The rod (index into [`RODS`]) with a compliance of its own, if any; the others share
    /// one.
    own: Option<usize>,
    /// `preload_elastic`, or `preload_elastic:rod2` with rod 2 of its own.
    name: String,
}

const NAME: &str = super::family::Family::PreloadElastic.name();

/// A rod with a compliance of its own, by name.
const PARTS: [&str; 5] = ["rod1", "rod2", "rod3", "rod4", "rod5"];

impl Default for PreloadElastic {
    fn default() -> Self {
        PreloadElastic {
            own: None,
            name: NAME.to_owned(),
        }
    }
}

impl PreloadElastic {
    /// Rod `rod` (index into [`RODS`]) with a compliance of its own.
    fn with_own(rod: usize) -> PreloadElastic {
        PreloadElastic {
            name: format!("{NAME}:{}", PARTS[rod]),
            own: Some(rod),
        }
    }

    /// Per rod, the index of the parameter that scales its stretch: the common one (0), or
    /// the rod's own (1).
    fn param_of_rod(&self) -> [usize; 5] {
        std::array::from_fn(|r| usize::from(self.own == Some(r)))
    }

    /// The common compliance, and the own rod's.
    fn params(&self) -> Vec<EffectParam> {
        // a rod cannot be stiffer than rigid: a negative compliance absorbs something else
        let compliance = |name: String| EffectParam::new(name, "x default", 1.0).within(0.0, 10.0);
        std::iter::once(compliance("compliance".to_owned()))
            .chain(
                self.own
                    .map(|r| compliance(format!("compliance_{}", PARTS[r]))),
            )
            .collect()
    }
}

impl Effect for PreloadElastic {
    fn name(&self) -> &str {
        &self.name
    }
    fn summary(&self) -> &'static str {
        "elastic deformation under internal preload, from the measured drive forces (a rod \
         of another stiffness with a compliance of its own)"
    }
    fn covariates(&self) -> &'static [&'static str] {
        &["f1", "f2", "f3", "f4"]
    }
    /// A rod with a compliance of its own, each rod in turn (none where one has it).
    fn refinements(&self) -> Vec<Box<dyn Effect>> {
        if self.own.is_some() {
            return Vec::new();
        }
        (0..RODS.len())
            .map(|r| Box::new(PreloadElastic::with_own(r)) as Box<dyn Effect>)
            .collect()
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
        let mut poses = Vec::with_capacity(campaign.poses.len());
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
                poses.push(None);
                continue;
            }
            loaded += 1;
            let by_others = moved.get(i).copied().unwrap_or_default();
            let (p, q) = by_others.applied(p, &pose.q);
            let at = Loaded::balanced(&p, &q, &pose.f, by_others.dq).map_err(|reason| {
                NotApplicable {
                    effect: self.name.clone(),
                    reason: format!("{}:{}: {reason}", campaign.source, pose.line),
                }
            })?;
            poses.push(Some(Box::new(at)));
        }
        if loaded == 0 {
            return Err(NotApplicable {
                effect: self.name.clone(),
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
            params: self.params(),
            of_rod: self.param_of_rod(),
            effect: self.clone(),
            poses,
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

/// Steps of the slope's forward differences: a micrometre of a length, a microradian of a
/// guide's angle. With them the rows' Jacobian is within 2.4e-5 of their sensitivity of the
/// balance made again at each displaced point (core/tests/it/effects_jacobian.rs).
const SLOPE_STEP_MM: f64 = 1e-3;
const SLOPE_STEP_RAD: f64 = 1e-6;

/// One loaded pose as bound: where its forces were balanced, the rods' stretch there and
/// how it moves with the pose's parameters and carrier positions.
struct Loaded {
    /// The parameters the forces were balanced at (the fit's, changed by the other
    /// effects) and the other effects' change of the carrier positions.
    p: Params,
    dq: [f64; 4],
    /// Rod stretch at the default stiffness, mm ...
    stretch: [f64; 5],
    /// ... and its slopes: forward differences of the whole balance, its passes at the
    /// deformed pose included (differentiated at the last pass alone, the slope of a
    /// parallelogram rod came out 0.14 % short, and a row's, a difference of rods, 2 %).
    over_p: [Row; 5],
    over_q: [[f64; 4]; 5],
}

impl Loaded {
    /// The pose of parameters `p`, carriers at `q` and drive forces `f` balanced, the other
    /// effects having moved its carriers by `dq`.
    fn balanced(p: &Params, q: &[f64; 4], f: &[f64; 4], dq: [f64; 4]) -> Result<Loaded, String> {
        let t = rod_forces(p, q, f)?;
        let stretch_of = |t: [f64; 5]| t.map(|t| t / DEFAULT_ROD_STIFFNESS_N_PER_MM);
        let stretch = stretch_of(t);
        let mut over_p = [Row::zeros(); 5];
        for j in 0..N_PARAMS {
            let h = if j == GAMMA1 || j == GAMMA2 {
                SLOPE_STEP_RAD
            } else {
                SLOPE_STEP_MM
            };
            let mut moved = *p;
            moved[j] += h;
            let s = stretch_of(rod_forces(&moved, q, f)?);
            for (r, g) in over_p.iter_mut().enumerate() {
                g[j] = (s[r] - stretch[r]) / h;
            }
        }
        let mut over_q = [[0.0; 4]; 5];
        for a in 0..4 {
            let mut moved = *q;
            moved[a] += SLOPE_STEP_MM;
            let s = stretch_of(rod_forces(p, &moved, f)?);
            for (r, g) in over_q.iter_mut().enumerate() {
                g[a] = (s[r] - stretch[r]) / SLOPE_STEP_MM;
            }
        }
        Ok(Loaded {
            p: *p,
            dq,
            stretch,
            over_p,
            over_q,
        })
    }
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
    /// Per rod, the parameter that scales its stretch.
    of_rod: [usize; 5],
    /// What it was bound from, to bind again.
    effect: PreloadElastic,
    /// Per pose, None where it is not loaded.
    poses: Vec<Option<Box<Loaded>>>,
}

impl Bound for BoundPreload {
    fn params(&self) -> &[EffectParam] {
        &self.params
    }
    /// The rod forces balance the drive forces through the rods' directions at the pose:
    /// 0.1 mm of parameter error turns them by 1e-4, their 1-10 kN by 0.3 %, a third of a
    /// micrometre of stretch on rods the instrument rows measure to a few hundredths.
    fn rebinds_from(&self) -> Option<&dyn Effect> {
        Some(&self.effect)
    }
    fn correct(&self, pose: usize, theta: &[f64], value: &mut Delta, partials: &mut [Delta]) {
        let Some(at) = &self.poses[pose] else {
            return;
        };
        for (r, rod) in RODS.iter().enumerate() {
            let k = self.of_rod[r];
            value.dp[rod.l] += theta[k] * at.stretch[r];
            partials[k].dp[rod.l] += at.stretch[r];
        }
    }
    /// The stretch at `p` changed by `moved` to first order from where the forces were
    /// balanced.
    fn correct_at(
        &self,
        pose: usize,
        theta: &[f64],
        (p, moved): (&Params, &Delta),
        value: &mut Delta,
        partials: &mut [Delta],
        slopes: &mut Vec<Slope>,
    ) {
        let Some(at) = &self.poses[pose] else {
            return;
        };
        let dp = Row::from_fn(|j, _| p[j] + moved.dp[j] - at.p[j]);
        let dq: [f64; 4] = std::array::from_fn(|a| moved.dq[a] - at.dq[a]);
        for (r, rod) in RODS.iter().enumerate() {
            let moves = (0..4).map(|a| at.over_q[r][a] * dq[a]).sum::<f64>();
            let s = at.stretch[r] + at.over_p[r].dot(&dp) + moves;
            let (k, c) = (self.of_rod[r], theta[self.of_rod[r]]);
            value.dp[rod.l] += c * s;
            partials[k].dp[rod.l] += s;
            slopes.push(Slope {
                param: rod.l,
                dp: c * at.over_p[r],
                dq: at.over_q[r].map(|g| c * g),
            });
        }
    }
}
