//! Circular test evaluation on the twin: a circle commanded with the controller's (nominal)
//! parameters on a machine with geometric errors deviates from its programmed radius; the
//! same circle on the nominal machine is round to the noise.

use rpkm_core::campaign::Instrument;
use rpkm_core::circular;
use rpkm_core::design::CIRCLE_RADIUS_MM;
use rpkm_core::params::Params;
use rpkm_twin::{Twin, TwinConfig};

#[test]
fn circle_on_an_erroneous_machine_deviates_and_on_a_nominal_one_does_not() {
    let mut bad = Twin::new(TwinConfig {
        seed: 3,
        ..Default::default()
    })
    .expect("twin");
    let c = bad.campaign(&[Instrument::Circle]).expect("circle");
    let r = circular::evaluate(&c, CIRCLE_RADIUS_MM);
    assert_eq!(r.len(), 1);
    assert!(r[0].points >= 36);
    let mut good = Twin::new(TwinConfig {
        seed: 3,
        length_sigma_mm: 0.0,
        angle_sigma_rad: 0.0,
        controller: Params::nominal(),
        ..Default::default()
    })
    .expect("twin");
    let g = circular::evaluate(
        &good.campaign(&[Instrument::Circle]).expect("circle"),
        CIRCLE_RADIUS_MM,
    );
    // ball-bar noise 1 µm: a perfect machine shows the noise: the range of 73 draws is about 5 sigma
    assert!(
        g[0].circularity < 0.008 && g[0].radius_deviation < 0.002,
        "{g:?}"
    );
    assert!(
        r[0].circularity > 3.0 * g[0].circularity && r[0].radius_deviation > 0.005,
        "errors must show: {r:?} vs {g:?}"
    );
}
