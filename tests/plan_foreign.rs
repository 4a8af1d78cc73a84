//! Issue 28 on the independent simulator's machine without hidden effects
//! (`../shared/campaigns/foreign/null`): its self-calibration rows alone, then 20 tracker
//! poses planned by `rpkm_core::plan` and measured on that machine (its true parameters,
//! `truth.json`, and its tracker noise, 5 µm per coordinate), determine at least 90 % of the
//! parameter combinations its whole campaign (tracker, grid encoder, ball-bar, self) does; 20
//! random tracker poses determine fewer. "Determined" is the calibration's own count
//! (`Calibration::determined`), with the noise estimated from the data, as `rpkm calibrate`.

mod foreign_support;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rpkm_core::analysis::nominal_campaign;
use rpkm_core::calib::{Options, Prior, Selection};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::design::{PlannedPose, CENTRE, X_RANGE, Y_RANGE};
use rpkm_core::effects::EffectSet;
use rpkm_core::params::{self, Model, Params};
use rpkm_core::plan::{self, Start, Unknowns};
use rpkm_core::variance;

const BUDGET: usize = 20;
/// The foreign tracker's noise per coordinate (its README), mm.
const TRACKER_MM: f64 = 0.005;

fn options() -> Options {
    Options {
        model: Model::M29,
        selection: Selection::Prior(Prior::default()),
        ..Default::default()
    }
}

/// The calibration's count of determined combinations, noise estimated as `rpkm calibrate`.
fn determined(c: &Campaign) -> (usize, usize, Params, rpkm_core::noise::NoiseModel) {
    let (cal, noise) = variance::calibrate_estimating_noise(
        c,
        &Params::nominal(),
        &options(),
        &EffectSet::empty(),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", c.source));
    let (d, n) = cal.determined.expect("a prior calibration counts");
    (d, n, cal.params, noise.model)
}

fn true_params(dir: &std::path::Path) -> Params {
    let truth = foreign_support::json(&dir.join("truth.json"));
    let mut p = Params::nominal();
    for (name, v) in truth["P_true"].as_object().expect("P_true") {
        let name = match name.as_str() {
            "g1" => "gamma1",
            "g2" => "gamma2",
            other => other,
        };
        p[params::index_of(name).expect("a parameter")] = v.as_f64().expect("a number");
    }
    p
}

/// `design` measured on the foreign machine: drive positions and readings of its true
/// parameters, the tracker's noise added to every reading.
fn measured(design: &[PlannedPose], truth: &Params, seed: u64) -> Campaign {
    let mut c = nominal_campaign(design, truth, Model::M29).expect("reachable");
    let mut rng = StdRng::seed_from_u64(seed);
    let n = Normal::new(0.0, TRACKER_MM).expect("a normal");
    for p in c.poses.iter_mut().filter(|p| !p.reset) {
        p.x = p.x.map(|x| x + n.sample(&mut rng));
        p.y = p.y.map(|y| y + n.sample(&mut rng));
    }
    c
}

/// The self rows followed by `extra`, as one campaign (times after the self rows').
fn with(self_rows: &Campaign, extra: &Campaign, name: &str) -> Campaign {
    let mut c = self_rows.clone();
    c.source = name.to_owned();
    let t0 = c.poses.last().map_or(0.0, |p| p.t) + 120.0;
    for (k, p) in extra.poses.iter().enumerate() {
        let mut p = p.clone();
        p.t = t0 + 10.0 * k as f64;
        p.covariates = vec![Some(20.0); c.covariate_names.len()];
        p.line = c.poses.len() + 3;
        c.poses.push(p);
    }
    c
}

fn random_design(seed: u64) -> Vec<PlannedPose> {
    let mut rng = StdRng::seed_from_u64(seed);
    let pose = |reset: bool, x: f64, y: f64| PlannedPose {
        setup: "random_lt".to_owned(),
        instrument: Instrument::Lt,
        reset,
        x,
        y,
    };
    let mut d = vec![pose(true, CENTRE.0, CENTRE.1)];
    for _ in 1..BUDGET {
        d.push(pose(
            false,
            rng.gen_range(X_RANGE.0..=X_RANGE.1),
            rng.gen_range(Y_RANGE.0..=Y_RANGE.1),
        ));
    }
    d
}

#[test]
fn planned_tracker_poses_determine_what_the_whole_campaign_does() {
    let Some(dir) = foreign_support::dataset("null") else {
        return;
    };
    let text = std::fs::read_to_string(dir.join("cal.csv")).expect("cal.csv");
    let full = Campaign::parse(&text, "null/cal.csv").expect("a campaign");
    let truth = true_params(&dir);
    let (d_full, n, _, _) = determined(&full);
    let mut self_only = full.clone();
    self_only.source = "null/cal.csv self rows".to_owned();
    self_only
        .poses
        .retain(|p| p.instrument == Instrument::SelfCal);
    let (d_self, _, params, noise) = determined(&self_only);
    let start = Start {
        campaign: &self_only,
        params: &params,
        model: Model::M29,
        noise: &noise,
    };
    let unknowns = Unknowns::of_model(Model::M29, |i| Prior::default().sigma(i));
    let plan =
        plan::plan_determination(&start, &unknowns, &[Instrument::Lt], BUDGET).expect("a plan");
    let design = plan.design();
    assert_eq!(design.len(), BUDGET);
    let planned = with(
        &self_only,
        &measured(&design, &truth, 1),
        "self + planned lt",
    );
    let (d_planned, _, _, _) = determined(&planned);
    let randoms: Vec<usize> = (0..5)
        .map(|s| {
            let c = with(
                &self_only,
                &measured(&random_design(s), &truth, 1),
                "self + random lt",
            );
            determined(&c).0
        })
        .collect();
    let mean_random = randoms.iter().sum::<usize>() as f64 / randoms.len() as f64;
    eprintln!(
        "determined of {n}: full campaign {d_full}, self rows {d_self}, planner's prediction {}, \
         self + 20 planned lt {d_planned}, self + 20 random lt {randoms:?} (mean {mean_random})",
        plan.after().determined
    );
    assert!(
        d_self < d_full,
        "the self rows alone leave something to plan"
    );
    assert!(
        d_planned as f64 >= 0.9 * d_full as f64,
        "planned: {d_planned} of the full campaign's {d_full}"
    );
    assert!(
        mean_random < d_planned as f64,
        "random poses: {randoms:?} against the plan's {d_planned}"
    );
}
