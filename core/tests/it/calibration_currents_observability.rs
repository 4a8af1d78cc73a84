//! What the drive forces determine (`rpkm analyze observability --method currents`), against
//! physics the analysis does not use:
//! - a machine consistent with the parameters holds no preload: on the 231-point grid the
//!   stiffness factor's column is zero, whatever the geometry's columns;
//! - the forces are the stiffness times the incompatibility, linear in both: on a twin's
//!   production path the stiffness factor's column is the geometric Jacobian times the true
//!   machine's distance from its controller's parameters (the twin's truth), so the geometry
//!   explains it and the forces alone cannot separate the two;
//! - one combination of forces per pose carries the geometry; the platform's angles γ1, γ2
//!   (which no balance of the others compensates) come first, as the offline calibration finds.

use rpkm_core::analysis::{self, Method, ObservabilityOptions};
use rpkm_core::design;
use rpkm_core::noise::NoiseModel;
use rpkm_core::params::{Model, Params, NAMES, N_PARAMS};
use rpkm_twin::{EffectKind, Twin, TwinConfig};

fn twin(seed: u64) -> Twin {
    let elastic = EffectKind::PreloadElastic;
    Twin::new(TwinConfig {
        seed,
        effects: vec![(elastic, elastic.default_magnitude())],
        noise: Some(NoiseModel {
            force_n: 3.0,
            ..NoiseModel::default()
        }),
        ..Default::default()
    })
    .expect("twin")
}

#[test]
fn on_the_grid_a_compatible_machine_shows_no_stiffness() {
    let o = analysis::observability(
        Method::Currents,
        &Params::nominal(),
        Model::M29,
        &[],
        &ObservabilityOptions::default(),
    )
    .expect("grid analysis");
    assert_eq!(o.rows, 4 * 231);
    let k = o
        .stiffness
        .expect("the currents analyse the stiffness factor");
    assert!(k.column_norm < 1e-6, "stiffness column {}", k.column_norm);
    let first = o.first(2);
    assert!(
        first.contains(&"gamma1") && first.contains(&"gamma2"),
        "{first:?}"
    );
    assert!(
        (5..=15).contains(&o.practical_rank),
        "practical rank {}: one force combination per pose, some combinations",
        o.practical_rank
    );
}

#[test]
fn on_a_production_path_the_stiffness_is_the_geometrys_distance_from_the_controller() {
    let mut t = twin(23);
    let truth = *t.true_params();
    let ctrl_by_name = t.truth().controller;
    let mut ctrl = Params::nominal();
    for (i, name) in NAMES.iter().enumerate() {
        ctrl[i] = ctrl_by_name[*name];
    }
    let path = t
        .run(&design::production(200, 23), "production")
        .expect("production path");
    let rows = analysis::currents_rows(&path, &truth).expect("force rows");
    // the stiffness column against J · (truth − controller): linear physics, not the analysis
    let (mut diff, mut norm) = (0.0, 0.0);
    for r in &rows {
        let geometric: f64 = (0..N_PARAMS)
            .map(|i| r.jacobian[i] * (truth[i] - ctrl[i]))
            .sum();
        diff += (r.d_theta[0] - geometric).powi(2);
        norm += r.d_theta[0].powi(2);
    }
    let rel = (diff / norm).sqrt();
    assert!(norm.sqrt() > 1e3, "preloaded path: stiffness column {norm}");
    assert!(
        rel < 0.05,
        "stiffness column vs geometry's: {rel:.4} relative"
    );

    let o = analysis::observability_of_rows(
        &rows,
        Method::Currents,
        Model::M29,
        &[],
        &ObservabilityOptions::default(),
    );
    let k = o.stiffness.expect("stiffness analysed");
    assert!(k.explained() > 0.999, "explained {}", k.explained());
    assert!(
        k.sigma_free() > analysis::STIFFNESS_RANGE,
        "forces alone would give the stiffness σ {} (relative)",
        k.sigma_free()
    );
    let first = o.first(2);
    assert!(
        first.contains(&"gamma1") && first.contains(&"gamma2"),
        "{first:?}"
    );
}
