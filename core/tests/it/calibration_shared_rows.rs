//! Rows shared by several calibrations (the diagnosis's candidates, `calib::SharedRows`) give
//! each the calibration it makes from rows it evaluates itself, to the bit; rows shared at
//! another point are not read.

use rpkm_core::calib::{calibrate, Calibration, Options, Request, SharedRows, WarmStart};
use rpkm_core::campaign::Instrument;
use rpkm_core::effects::{self, Effect, EffectSet};
use rpkm_core::params::{Params, N_PARAMS};
use rpkm_twin::{EffectKind, Twin, TwinConfig};

/// Whether two calibrations are the same to the bit: parameters, effect parameters, every
/// row's value, χ², leverages, iterations.
fn assert_same(a: &Calibration, b: &Calibration, what: &str) {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let params = |c: &Calibration| (0..N_PARAMS).map(|i| c.params[i]).collect::<Vec<_>>();
    assert_eq!(bits(&params(a)), bits(&params(b)), "{what}: parameters");
    assert_eq!(bits(&a.theta), bits(&b.theta), "{what}: θ");
    let values = |c: &Calibration| c.residuals.iter().map(|r| r.value).collect::<Vec<_>>();
    assert_eq!(bits(&values(a)), bits(&values(b)), "{what}: rows");
    assert_eq!(bits(&a.leverage), bits(&b.leverage), "{what}: leverages");
    let figures = |c: &Calibration| [c.chi2_per_dof, c.cost_after, c.dof_model];
    assert_eq!(bits(&figures(a)), bits(&figures(b)), "{what}: χ²");
    assert_eq!(
        (a.iterations, a.screened),
        (b.iterations, b.screened),
        "{what}: iterations"
    );
}

/// Every effect of the library that binds to a twin campaign hiding thermal expansion, added
/// to the model and fitted from the model's minimum (a diagnosis's candidates, screened and
/// to convergence): the calibration that reads its rows at the start and at the warm start
/// from rows shared with the others is the one that evaluates its own.
#[test]
fn shared_rows_give_the_calibration_of_own_rows() {
    let hidden = EffectKind::Thermal;
    let mut twin = Twin::new(TwinConfig {
        seed: 5,
        effects: vec![(hidden, hidden.default_magnitude())],
        ..Default::default()
    })
    .expect("twin");
    let campaign = twin
        .campaign(&[Instrument::Lt, Instrument::Kgm])
        .expect("campaign");
    let opts = Options {
        outlier_sigma: None,
        ..Default::default()
    };
    let start = Params::nominal();
    let (base, _) = calibrate(&Request::new(&campaign, &start, &opts)).expect("current model");
    let library = effects::library();
    let tried: Vec<&dyn Effect> = library
        .iter()
        .map(AsRef::as_ref)
        .filter(|e| EffectSet::bind(&[*e], &campaign, &start).is_ok())
        .collect();
    assert!(tried.len() >= 4, "{} effects bind", tried.len());
    let union = EffectSet::bind(&tried, &campaign, &start).expect("union");
    let zero = vec![0.0; union.n_params()];
    let at = |p: &Params| {
        SharedRows::new(&campaign, &start, &opts, &union, (p, &zero)).expect("shared rows")
    };
    let (shared, elsewhere) = (at(&base.params), at(&start));
    for effect in &tried {
        let set = EffectSet::bind(&[*effect], &campaign, &start).expect("candidate");
        let theta = vec![0.0; set.n_params()];
        for screen in [true, false] {
            let warm = WarmStart {
                params: &base.params,
                theta: &theta,
                screen,
            };
            let own_rows = Request {
                effects: &set,
                warm: Some(warm),
                ..Request::new(&campaign, &start, &opts)
            };
            let (own, _) = calibrate(&own_rows).expect("own rows");
            for rows in [&shared, &elsewhere] {
                let (read, _) = calibrate(&Request {
                    shared: Some(rows),
                    ..own_rows
                })
                .expect("shared rows");
                assert_same(&own, &read, effect.name());
            }
        }
    }
}
