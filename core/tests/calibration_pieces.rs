//! A calibration sums its rows piece by piece, on any number of threads: the result must not
//! depend on the thread count (to the bit), and a campaign of many pieces (a setup cut in
//! several, a forward instrument's step 2 among them) must still find the true machine.

mod support;

use rpkm_core::calib::{self, Options};
use rpkm_core::design;
use rpkm_core::params::{Model, Params, NAMES};

/// Every instrument, twice over (about 2,000 poses: several pieces per setup), noisy.
fn campaign(seed: u64) -> (rpkm_core::campaign::Campaign, Params) {
    let truth = support::true_params(seed, false);
    let plan: Vec<_> = [
        design::lt(),
        design::kgm(),
        design::dbb(),
        design::li_x(),
        design::self_cal(),
    ]
    .concat();
    let twice = [plan.clone(), plan].concat();
    (
        support::measure(&twice, &truth, seed, true, "pieces"),
        truth,
    )
}

#[test]
fn one_two_and_three_threads_give_the_same_calibration_to_the_bit() {
    let (c, _) = campaign(5);
    let run = |threads| {
        let opts = Options {
            model: Model::M29,
            threads,
            ..Default::default()
        };
        calib::calibrate(&calib::Request::new(&c, &Params::nominal(), &opts))
            .map(|(cal, _)| cal)
            .expect("the twin's campaign calibrates")
    };
    let one = run(1);
    for threads in [2, 3] {
        let other = run(threads);
        for (i, name) in NAMES.iter().enumerate() {
            assert_eq!(
                one.params[i].to_bits(),
                other.params[i].to_bits(),
                "{name} on {threads} threads"
            );
        }
        assert_eq!(one.iterations, other.iterations);
        assert_eq!(one.cost_after.to_bits(), other.cost_after.to_bits());
        let sigmas = |c: &calib::Calibration| {
            c.identified
                .iter()
                .map(|i| i.sigma.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(sigmas(&one), sigmas(&other));
        let lev =
            |c: &calib::Calibration| c.leverage.iter().map(|h| h.to_bits()).collect::<Vec<_>>();
        assert_eq!(lev(&one), lev(&other));
    }
}

/// Against the machine the campaign was measured on: every identified parameter within 4σ of
/// its true value, χ²/dof near 1 (the twin's noise is the stated noise here), the leverages
/// summing to the parameters the data determine.
#[test]
fn a_campaign_of_many_pieces_finds_the_true_machine() {
    let (c, truth) = campaign(9);
    let opts = Options {
        model: Model::M29,
        threads: 2,
        ..Default::default()
    };
    let cal = calib::calibrate(&calib::Request::new(&c, &Params::nominal(), &opts))
        .map(|(cal, _)| cal)
        .expect("the twin's campaign calibrates");
    assert!(cal.rows > 2000, "{} rows", cal.rows);
    for id in &cal.identified {
        let z = (id.value - truth[id.index]) / id.sigma;
        assert!(z.abs() < 4.0, "{}: z = {z:.2}", id.name);
    }
    assert!(
        (0.8..1.25).contains(&cal.chi2_per_dof),
        "chi2/dof {}",
        cal.chi2_per_dof
    );
    let trace: f64 = cal.leverage.iter().sum();
    assert!(
        (trace - cal.dof_model).abs() < 1e-6 * cal.dof_model,
        "Σ leverage {trace} vs {}",
        cal.dof_model
    );
    assert!(cal.iterations <= 10, "{} iterations", cal.iterations);
}

/// Pieces cross setups only where the rows read no reset pose: evaluated piece by piece and
/// concatenated, the rows are those of one pass over the campaign, in the same order and to
/// the bit, whatever the pieces' size; a self-calibration campaign of 1,043 poses in several
/// setups makes ⌈1043 / 256⌉ = 5 pieces.
#[test]
fn pieces_across_setups_give_the_rows_of_one_pass() {
    use rpkm_core::effects::Corrections;
    use rpkm_core::noise::NoiseModel;
    use rpkm_core::obs::{residuals_in, Evaluation, Form, Pieces, Residual, Step};
    let truth = support::true_params(3, false);
    let selfs = vec![design::self_cal(); 7].concat();
    let mixed = [
        design::self_cal(),
        design::lt(),
        design::self_cal(),
        design::dbb(),
        design::self_cal(),
    ]
    .concat();
    let p = Params::nominal();
    let (corr, noise) = (Corrections::default(), NoiseModel::default());
    let key = |r: &Residual| (r.pose, r.direction, r.value.to_bits(), r.sigma.to_bits());
    for (plan, name) in [(selfs, "self"), (mixed, "mixed")] {
        let c = support::measure(&plan, &truth, 4, true, name);
        for step in [Step::Direct, Step::VirtualQ2] {
            let eval = Evaluation {
                campaign: &c,
                p: &p,
                model: Model::M29,
                step,
                p_cal: &p,
                corr: &corr,
                noise: &noise,
                form: Form::Decorrelated,
            };
            let whole =
                residuals_in(&c, &p, Model::M29, step, &p, &corr, &noise, eval.form).expect("rows");
            for size in [1, 7, 100, 256] {
                let pieces = Pieces::new(&c, size);
                let mut rows = Vec::new();
                for k in 0..pieces.len() {
                    eval.piece_into(&pieces, k, &mut rows).expect("piece");
                }
                assert_eq!(
                    rows.iter().map(key).collect::<Vec<_>>(),
                    whole.iter().map(key).collect::<Vec<_>>(),
                    "{name}, {step:?}, pieces of {size}"
                );
            }
        }
        if name == "self" {
            assert_eq!(c.poses.len(), 1043);
            assert!(c.setups().len() > 1, "{} setups", c.setups().len());
            assert_eq!(Pieces::new(&c, 256).len(), 5);
        }
    }
}
