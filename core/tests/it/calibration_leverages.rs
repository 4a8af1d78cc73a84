//! A calibration that asks for no leverages (`Request::leverages`, the diagnosis's
//! candidates) is the calibration that makes them, to the bit, less the leverages; the noise
//! rounds, which read them, make them whatever the request says.

use rpkm_core::calib::{calibrate, Calibration, Noise, Options, Request, WarmStart};
use rpkm_core::campaign::Instrument;
use rpkm_core::effects::{self, EffectSet};
use rpkm_core::params::{Params, N_PARAMS};
use rpkm_twin::{EffectKind, Twin, TwinConfig};

/// Every number of two calibrations but their leverages, as bits.
fn figures(c: &Calibration) -> Vec<u64> {
    (0..N_PARAMS)
        .map(|i| c.params[i])
        .chain(c.theta.iter().copied())
        .chain(c.residuals.iter().map(|r| r.value))
        .chain([c.chi2_per_dof, c.cost_after, c.dof_model])
        .chain(c.covariance.iter().copied())
        .map(f64::to_bits)
        .collect()
}

#[test]
fn a_calibration_without_leverages_is_the_same_calibration() {
    let hidden = EffectKind::Thermal;
    let mut twin = Twin::new(TwinConfig {
        seed: 3,
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
    let thermal = library
        .iter()
        .find(|e| e.name() == "thermal")
        .expect("thermal in the library");
    let set = EffectSet::bind(&[thermal.as_ref()], &campaign, &start).expect("thermal binds");
    let theta = vec![0.0; set.n_params()];
    for screen in [true, false] {
        let with = Request {
            effects: &set,
            warm: Some(WarmStart {
                params: &base.params,
                theta: &theta,
                screen,
            }),
            ..Request::new(&campaign, &start, &opts)
        };
        let (made, _) = calibrate(&with).expect("with leverages");
        let (none, _) = calibrate(&Request {
            leverages: false,
            ..with
        })
        .expect("without leverages");
        assert_eq!(made.leverage.len(), made.residuals.len(), "screen {screen}");
        assert!(made.leverage.iter().all(|h| (0.0..=1.0).contains(h)));
        assert!(none.leverage.is_empty(), "screen {screen}: leverages made");
        assert_eq!(figures(&made), figures(&none), "screen {screen}");
    }
    // the noise rounds read the leverages: asked for none, they are made, and the estimate
    // is the same
    let estimated = Request {
        noise: Noise::ESTIMATE,
        ..Request::new(&campaign, &start, &opts)
    };
    let (a, est_a) = calibrate(&estimated).expect("estimated");
    let (b, est_b) = calibrate(&Request {
        leverages: false,
        ..estimated
    })
    .expect("estimated, no leverages asked");
    assert_eq!(a.leverage.len(), a.residuals.len());
    assert_eq!(
        a.leverage.iter().map(|h| h.to_bits()).collect::<Vec<_>>(),
        b.leverage.iter().map(|h| h.to_bits()).collect::<Vec<_>>()
    );
    assert_eq!(figures(&a), figures(&b));
    assert_eq!(est_a.rounds, est_b.rounds);
    assert_eq!(est_a.model, est_b.model);
}
