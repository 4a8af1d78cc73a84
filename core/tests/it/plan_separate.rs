//! Issue 28: a twin machine whose carrier 4 has lost motion, measured by a follower
//! self-calibration (q2, q3 followers): carriers 2 and 4 move together along its lines, so
//! the diagnosis's pointer ties `dir_q2` and `dir_q4`. The plan that separates them, measured
//! on the same machine, lets the diagnosis point at `dir_q4` alone.

use rpkm_core::calib::{self, Noise, Prior, Request};
use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::design;
use rpkm_core::diagnose::{self, DiagnosisOptions};
use rpkm_core::params::{Model, Params};
use rpkm_core::plan::separate::{self, Hypothesis, Pair};
use rpkm_core::plan::{self, Unknowns};
use rpkm_twin::{EffectKind, Twin, TwinConfig};

/// The lost motion, mm (10 µm: 20 times the encoders' σ).
const LOST_MM: f64 = 0.01;
const BUDGET: usize = 60;

fn pointer(c: &Campaign) -> diagnose::structure::sparse::Pointer {
    let d = diagnose::diagnose(c, None, &[], &DiagnosisOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", c.source));
    d.structure.pointer.expect("a term the residual follows")
}

#[test]
fn the_separating_plan_names_dir_q4_alone() {
    let mut twin = Twin::new(TwinConfig {
        seed: 11,
        effects: vec![(EffectKind::LostMotionQ4, LOST_MM)],
        ..TwinConfig::default()
    })
    .expect("a twin");
    let campaign = twin.run(&design::self_cal(), "self").expect("measured");
    let before = pointer(&campaign);
    let tied = [before.feature.as_str()]
        .into_iter()
        .chain(before.ties.iter().map(String::as_str))
        .collect::<Vec<_>>();
    assert!(
        tied.contains(&"dir_q2") && tied.contains(&"dir_q4"),
        "the follower self-calibration ties them: {} ties {:?}",
        before.feature,
        before.ties
    );
    let opts = diagnose::calib_options(&DiagnosisOptions::default());
    let start = Params::nominal();
    let (cal, noise) = calib::calibrate(&Request {
        noise: Noise::ESTIMATE,
        ..Request::new(&campaign, &start, &opts)
    })
    .expect("calibrated");
    let prior = Prior::default();
    let unknowns = Unknowns::of_model(Model::M24, |i| prior.sigma(i));
    let pair = Pair::new(
        Hypothesis::LostMotion(1),
        Hypothesis::LostMotion(3),
        LOST_MM,
        &|i| prior.sigma(i),
    )
    .expect("two hypotheses");
    let model = (Model::M24, &noise.model);
    let now =
        separate::separation_of(&campaign, &cal.params, model, &unknowns, &pair).expect("rows");
    let setup = plan::candidates(&[Instrument::SelfCal])
        .expect("self")
        .remove(0);
    let p =
        separate::separate(&setup, &cal.params, model, &unknowns, &pair, BUDGET).expect("a plan");
    let expected = p.after().expect("poses").sigma();
    eprintln!(
        "dir_q2 against dir_q4: the self-calibration {:.2} sigma, the plan of {} poses {expected:.2} sigma",
        now.sigma(),
        p.poses.len()
    );
    // the campaign's own rows tell the two lost motions apart only through how differently
    // q2's and q4's readings move the rows (the dictionary's sign columns tie); the plan's
    // moves make the signs differ
    assert!(
        expected > 3.0 * now.sigma() && expected > 5.0,
        "the plan separates them: {expected} against {now:?}"
    );
    let planned = twin.run(&p.poses, "planned").expect("measured");
    let after = pointer(&planned);
    eprintln!(
        "after the plan: {} (r = {:.2}), ties {:?}",
        after.feature, after.r, after.ties
    );
    assert_eq!(after.feature, "dir_q4");
    assert!(after.ties.is_empty(), "ties: {:?}", after.ties);
}
