//! Issue 28 against the thesis's campaigns (tables 4.4-4.8): for each method's design, the
//! parameters its observability analysis identifies (QR-pivot order of the weighted,
//! range-scaled Jacobian, kept while the condition number stays below 100, as `--params
//! auto`), and a planned campaign of as many poses with the same instruments: the condition
//! number of the column-normalised weighted Jacobian over those parameters is equal or
//! better. The figures are in docs/observability.md ("Planned against the thesis's designs").

use nalgebra::DMatrix;
use rpkm_core::analysis::{jacobian, Method};
use rpkm_core::noise::NoiseModel;
use rpkm_core::observability::qr_pivot_order;
use rpkm_core::params::{variation_range, Model, Params};
use rpkm_core::plan::{self, Unknowns};

/// Schröer's limit of `--params auto`.
const MAX_CONDITION: f64 = 100.0;

/// (thesis design's condition, planned condition, parameters, poses) of one method.
fn compare(method: Method, model: Model) -> (f64, f64, usize, usize) {
    let p = Params::nominal();
    let noise = NoiseModel::default();
    let design = method.design();
    let rows = plan::design_rows(&design, &p, model, &noise).expect("rows");
    let all = model.params();
    let range = DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
        all.len(),
        all.iter().map(|&i| variation_range(i)),
    ));
    let ids: Vec<usize> = qr_pivot_order(&(jacobian(&rows, &all, true) * range))
        .into_iter()
        .take_while(|r| r.condition_number < MAX_CONDITION)
        .map(|r| all[r.column])
        .collect();
    let unknowns = Unknowns {
        tolerance: ids.iter().map(|&i| variation_range(i)).collect(),
        ids: ids.clone(),
    };
    let planned = plan::plan_like(&design, &p, model, &noise, &unknowns).expect("a plan");
    let planned_design = planned.design();
    assert_eq!(
        planned_design.len(),
        design.len(),
        "{method}: the same size"
    );
    let planned_rows = plan::design_rows(&planned_design, &p, model, &noise).expect("rows");
    (
        plan::condition(&rows, &ids),
        plan::condition(&planned_rows, &ids),
        ids.len(),
        design.len(),
    )
}

#[test]
fn planned_campaigns_are_conditioned_as_well_as_the_thesis_designs() {
    let cases = [
        (Method::Lt, Model::M24),
        (Method::Lt, Model::M29),
        (Method::Kgm, Model::M24),
        (Method::Kgm, Model::M29),
        (Method::Dbb, Model::M24),
        (Method::Dbb, Model::M29),
        (Method::Psi, Model::M29),
        (Method::SelfCal, Model::M24),
        (Method::SelfCal, Model::M29),
    ];
    let mut worse = Vec::new();
    for (method, model) in cases {
        let (thesis, planned, n, poses) = compare(method, model);
        eprintln!(
            "| {method} | {} | {poses} | {n} | {thesis:.1} | {planned:.1} |",
            model.number()
        );
        if !(planned <= thesis * (1.0 + 1e-9)) {
            worse.push(format!("{method} {}: {planned} > {thesis}", model.number()));
        }
    }
    assert!(worse.is_empty(), "planned worse: {worse:?}");
}
