//! Calibration on generated rigid-geometry campaigns, one test per instrument path.
//!
//! Two checks each, against the true machine:
//! - with errors on the parameters this campaign can identify (the observability selection),
//!   every identified value lies within 3 sigma of its true value;
//! - the held-out RMS after calibration is within 1.2x of the noise floor (the RMS that the
//!   true parameters give on the same held-out poses): held-out laser-tracker poses, or, for
//!   the ball-bar, held-out ball-bar readings (see [`HeldOut`]).

use crate::support;

use rand::Rng;
use rpkm_core::calib::{self, Calibration, Options, Selection};
use rpkm_core::campaign::Campaign;
use rpkm_core::design::{self, PlannedPose};
use rpkm_core::obs;
use rpkm_core::params::{unit, Model, Params, Unit};

fn val_rms_um(val: &Campaign, p: &Params, model: Model) -> f64 {
    let e: Vec<f64> = obs::tcp_errors(val, p, model)
        .expect("validation")
        .iter()
        .map(|e| e.value)
        .collect();
    1e3 * calib::rms(&e)
}

/// Parameters the design identifies (observability at nominal, condition number < 1e4).
fn identifiable(design: &[PlannedPose], model: Model) -> Vec<usize> {
    let c = support::measure(design, &Params::nominal(), 1, false, "plan");
    let opts = Options {
        model,
        selection: Selection::Auto { max_condition: 1e4 },
        outlier_sigma: None,
        ..Default::default()
    };
    let cal = calib::calibrate(&calib::Request::new(&c, &Params::nominal(), &opts))
        .map(|(cal, _)| cal)
        .expect("calibration at nominal");
    cal.identified.iter().map(|i| i.index).collect()
}

/// Which held-out readings judge a calibration.
#[derive(Clone, Copy, PartialEq)]
enum HeldOut {
    /// Laser-tracker poses over the workspace: what the machine's accuracy is.
    Tracker,
    /// A second campaign of the same design and instrument. A ball-bar reads distances from
    /// its pivots only: at the observability cut (condition 1e4) the 13 parameters it
    /// identifies are determined well enough to predict its own readings, not to bring the
    /// tracker's x, y to its noise floor (2-5 times the floor over 30 seeds, whichever way
    /// pivot ties are ranked).
    Own,
}

/// RMS (µm) of the direct rows of `c` under `p`: the misfit of the instrument's own readings.
fn own_rms_um(c: &Campaign, p: &Params, model: Model) -> f64 {
    let noise = rpkm_core::noise::NoiseModel::default();
    let rows = obs::residuals(c, p, model, obs::Step::Direct, p, &noise).expect("held-out rows");
    let values: Vec<f64> = rows.iter().map(|r| r.value).collect();
    1e3 * calib::rms(&values)
}

fn check(name: &str, design: &[PlannedPose], model: Model, seed: u64) -> Calibration {
    check_against(name, design, model, seed, HeldOut::Tracker)
}

fn check_against(
    name: &str,
    design: &[PlannedPose],
    model: Model,
    seed: u64,
    held_out: HeldOut,
) -> Calibration {
    let ids = identifiable(design, model);
    assert!(
        ids.len() >= 6,
        "{name}: only {} identifiable parameters",
        ids.len()
    );
    let mut rng = support::rng(seed);
    let mut truth = Params::nominal();
    for &i in &ids {
        truth[i] += if unit(i) == Unit::Rad {
            rng.gen_range(-3e-4..3e-4)
        } else {
            rng.gen_range(-0.3..0.3)
        };
    }
    if model == Model::M24 {
        truth = truth.with_perfect_parallelogram();
    }
    let c = support::measure(design, &truth, seed, true, name);
    let opts = Options {
        model,
        selection: Selection::List(ids.clone()),
        ..Default::default()
    };
    let cal = calib::calibrate(&calib::Request::new(&c, &Params::nominal(), &opts))
        .map_or_else(|e| panic!("{name}: {e}"), |(cal, _)| cal);
    for id in &cal.identified {
        let z = (id.value - truth[id.index]) / id.sigma;
        assert!(
            z.abs() < 3.0,
            "{name}: {} identified {} true {} sigma {:.2e} ({z:.1} sigma)",
            id.name,
            id.value,
            truth[id.index],
            id.sigma
        );
    }
    assert!(
        cal.chi2_per_dof < 1.5,
        "{name}: chi2/dof {}",
        cal.chi2_per_dof
    );
    let (after, floor, before) = match held_out {
        HeldOut::Tracker => {
            let val = support::validation(&truth, seed + 100);
            let rms = |p: &Params| val_rms_um(&val, p, model);
            (rms(&cal.params), rms(&truth), rms(&Params::nominal()))
        }
        HeldOut::Own => {
            let val = support::measure(design, &truth, seed + 100, true, "held-out.csv");
            let rms = |p: &Params| own_rms_um(&val, p, model);
            (rms(&cal.params), rms(&truth), rms(&Params::nominal()))
        }
    };
    assert!(
        after <= 1.2 * floor,
        "{name}: held-out {after:.2} um, floor {floor:.2} um (nominal {before:.2})"
    );
    // visible: the seeded errors must stand clear of the held-out noise
    assert!(
        before > 1.5 * floor,
        "{name}: the errors must be visible before calibration ({before:.2} um)"
    );
    cal
}

#[test]
fn laser_tracker_and_self_calibration_model_29() {
    check(
        "lt+self",
        &[design::lt(), design::self_cal()].concat(),
        Model::M29,
        21,
    );
}

#[test]
fn laser_tracker_model_24() {
    check("lt", &design::lt(), Model::M24, 22);
}

#[test]
fn grid_encoder_model_29() {
    check("kgm", &design::kgm(), Model::M29, 23);
}

#[test]
fn ball_bar_two_step_model_29() {
    let cal = check_against("dbb", &design::dbb(), Model::M29, 24, HeldOut::Own);
    assert!(
        cal.identified.iter().any(|i| i.step == 2),
        "the q2 branch comes from the virtual measurements"
    );
}

#[test]
fn interferometer_two_step_model_29() {
    let cal = check(
        "li",
        &[design::li_x(), design::li_y(), design::li_psi()].concat(),
        Model::M29,
        25,
    );
    assert!(cal.identified.iter().any(|i| i.step == 2));
}

#[test]
fn self_calibration_model_24() {
    check("self", &design::self_cal(), Model::M24, 26);
}

/// With errors on all 29 parameters, the full-pose instruments still reach the noise floor on
/// held-out poses: what they cannot identify cannot be seen in relative TCP measurements.
#[test]
fn full_pose_instruments_reach_the_noise_floor_with_all_errors() {
    for (name, design, seed) in [
        ("lt+self", [design::lt(), design::self_cal()].concat(), 31),
        ("kgm", design::kgm(), 32),
    ] {
        let truth = support::true_params(seed, false);
        let c = support::measure(&design, &truth, seed, true, name);
        let opts = Options {
            model: Model::M29,
            selection: Selection::Auto { max_condition: 1e5 },
            ..Default::default()
        };
        let cal = calib::calibrate(&calib::Request::new(&c, &Params::nominal(), &opts))
            .map(|(cal, _)| cal)
            .expect("calibration");
        let val = support::validation(&truth, seed + 100);
        let (after, floor) = (
            val_rms_um(&val, &cal.params, Model::M29),
            val_rms_um(&val, &truth, Model::M29),
        );
        assert!(
            after <= 1.2 * floor,
            "{name}: held-out {after:.2} um, floor {floor:.2} um"
        );
    }
}

#[test]
fn outliers_are_eliminated_and_reported() {
    let truth = support::true_params(41, false);
    let mut c = support::measure(&design::lt(), &truth, 41, true, "lt");
    c.poses[7].x = c.poses[7].x.map(|x| x + 0.5);
    let cal = calib::calibrate(&calib::Request::new(
        &c,
        &Params::nominal(),
        &Options {
            model: Model::M29,
            ..Default::default()
        },
    ))
    .map(|(cal, _)| cal)
    .expect("calibration");
    assert!(
        cal.outliers.iter().any(|o| o.line == c.poses[7].line),
        "{:?}",
        cal.outliers
    );
}

/// The dependency matrix D (eq. 3.35): with the perfect parallel-holder as links, model 29
/// identifies l4 and carries l5 along, so rod 5 stays rod 4 shifted, as on the true machine.
#[test]
fn linked_parameters_follow_their_masters() {
    use rpkm_core::params::{L4, L5, XB4R, XB5R};
    let mut truth = Params::nominal();
    truth[L4] += 0.2;
    truth[XB4R] -= 0.15;
    let truth = truth.with_perfect_parallelogram();
    let c = support::measure(
        &[design::lt(), design::self_cal()].concat(),
        &truth,
        51,
        true,
        "lt+self",
    );
    let opts = Options {
        model: Model::M29,
        selection: Selection::List(vec![L4, XB4R, rpkm_core::params::GAMMA2]),
        links: calib::Link::perfect_parallelogram(),
        ..Default::default()
    };
    let cal = calib::calibrate(&calib::Request::new(&c, &Params::nominal(), &opts))
        .map(|(cal, _)| cal)
        .expect("calibration");
    assert!(
        (cal.params[L4] - truth[L4]).abs() < 0.01,
        "l4 {} vs {}",
        cal.params[L4],
        truth[L4]
    );
    assert!(
        (cal.params[L5] - cal.params[L4]).abs() < 1e-9,
        "l5 follows l4"
    );
    assert!(
        (cal.params[XB5R] - cal.params[XB4R]).abs() < 1e-9,
        "xb5r follows xb4r"
    );
    assert!(
        cal.identified.iter().all(|i| i.index != L5),
        "l5 is linked, not identified"
    );
}

/// Effects bound to one campaign read their corrections by pose index: calibrating another
/// campaign with them is refused, naming both sizes, instead of correcting the wrong poses.
#[test]
fn effects_bound_to_another_campaign_are_refused() {
    let truth = Params::nominal();
    let lt = support::measure(&design::lt(), &truth, 3, true, "lt.csv");
    let kgm = support::measure(&design::kgm(), &truth, 4, true, "kgm.csv");
    assert_ne!(lt.poses.len(), kgm.poses.len());
    let scale = rpkm_core::effects::by_name("encoder_scale").expect("encoder_scale");
    let set = rpkm_core::effects::EffectSet::bind(&[scale.as_ref()], &lt, &truth)
        .expect("encoder_scale binds to the tracker campaign");
    let err = calib::calibrate(&calib::Request {
        effects: &set,
        ..calib::Request::new(&kgm, &truth, &Options::default())
    })
    .expect_err("another campaign's effects");
    let text = err.to_string();
    assert!(
        text.contains("kgm.csv")
            && text.contains(&lt.poses.len().to_string())
            && text.contains(&kgm.poses.len().to_string()),
        "{text}"
    );
}

/// Starting effect parameters of the wrong length are refused, naming both lengths, instead
/// of being replaced by zeros without a word.
#[test]
fn starting_effect_parameters_of_the_wrong_length_are_refused() {
    let truth = Params::nominal();
    let lt = support::measure(&design::lt(), &truth, 3, true, "lt.csv");
    let scale = rpkm_core::effects::by_name("encoder_scale").expect("encoder_scale");
    let set = rpkm_core::effects::EffectSet::bind(&[scale.as_ref()], &lt, &truth)
        .expect("encoder_scale binds");
    let n = set.n_params();
    let err = calib::calibrate(&calib::Request {
        effects: &set,
        theta0: &vec![0.0; n + 1],
        ..calib::Request::new(&lt, &truth, &Options::default())
    })
    .expect_err("one parameter too many");
    assert!(
        matches!(err, calib::CalibrationError::StartThetaLength { given, expected } if given == n + 1 && expected == n),
        "{err}"
    );
    calib::calibrate(&calib::Request {
        effects: &set,
        theta0: &vec![0.0; n],
        ..calib::Request::new(&lt, &truth, &Options::default())
    })
    .expect("the right length calibrates");
}

/// A reading of −1e300 mm (a campaign built in code, past the CSV reader's checks) must not
/// calibrate "successfully" with infinite uncertainties: the calibration refuses it.
#[test]
fn an_absurd_reading_is_refused_not_calibrated() {
    let truth = Params::nominal();
    let mut c = support::measure(&design::self_cal(), &truth, 5, true, "self.csv");
    c.poses[10].q[1] = -1e300;
    let opts = Options {
        model: Model::M24,
        ..Default::default()
    };
    match calib::calibrate(&calib::Request::new(&c, &truth, &opts)).map(|(cal, _)| cal) {
        Ok(cal) => panic!(
            "calibrated: chi2/dof {}, sigmas {:?}",
            cal.chi2_per_dof,
            cal.identified.iter().map(|i| i.sigma).collect::<Vec<_>>()
        ),
        Err(e) => {
            let text = e.to_string();
            let line = format!("self.csv:{}", c.poses[10].line);
            assert!(
                text.contains(&line) && text.contains("not finite"),
                "{text}"
            );
        }
    }
}

/// A reset pose the model cannot solve is blamed on its own line, not on the first pose
/// measured relative to it (the model rows and the held-out errors alike).
#[test]
fn an_unsolvable_reset_is_blamed_on_its_own_line() {
    let truth = Params::nominal();
    let mut c = support::measure(&design::lt(), &truth, 6, true, "lt.csv");
    let ri = c.poses.iter().position(|p| p.reset).expect("a reset pose");
    c.poses[ri].q[0] += 5_000.0;
    let line = format!("lt.csv:{}", c.poses[ri].line);
    let err = calib::calibrate(&calib::Request::new(&c, &truth, &Options::default()))
        .map(|(cal, _)| cal)
        .expect_err("unsolvable reset");
    assert!(err.to_string().contains(&line), "{err}");
    let err = obs::tcp_errors(&c, &truth, Model::M29).expect_err("unsolvable reset");
    assert!(err.to_string().contains(&line), "{err}");
}
