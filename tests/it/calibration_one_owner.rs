//! One owner for the calibration: `rpkm calibrate`, `rpkm diagnose` and the calibrator node
//! each make one call of `rpkm_core::calib::calibrate` from the same defaults, so one
//! campaign with one set of options gives the same parameters to the bit in all three (the
//! noise estimated from the campaign, no outlier elimination: the diagnosis's nested tests
//! need the same rows in every fit). On a machine whose noise is the stated one, so that the
//! diagnosis's first round, at the stated noise, finds no candidate to estimate the noise
//! under (the noise is then estimated under the model itself, as `rpkm calibrate` does).

use crate::foreign_support;

use rpkm_core::campaign::{Campaign, Instrument};
use rpkm_core::params::{unit, Model, Params, Unit, NAMES};
use rpkm_nodes::node::calibrator::{calibrate_campaign, CalibratorOptions};
use rpkm_nodes::node::Geometry;
use rpkm_twin::{Twin, TwinConfig};
use std::path::Path;
use std::process::Command;

fn rpkm_json(args: &[&str], out: &Path) -> serde_json::Value {
    let status = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .args(args)
        .arg("--json")
        .arg(out)
        .output()
        .expect("rpkm runs");
    assert!(
        status.status.success(),
        "rpkm {args:?}: {}",
        String::from_utf8_lossy(&status.stderr)
    );
    foreign_support::json(out)
}

/// The parameter `name` of a JSON object of parameters by name.
fn value(params: &serde_json::Value, name: &str) -> f64 {
    params[name]
        .as_f64()
        .unwrap_or_else(|| panic!("no parameter {name} in {params}"))
}

#[test]
fn calibrate_diagnose_and_the_calibrator_node_give_the_same_parameters() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let mut twin = Twin::new(TwinConfig {
        seed: 3,
        ..Default::default()
    })
    .expect("twin");
    let measured = twin
        .campaign(&[Instrument::Lt, Instrument::Kgm, Instrument::SelfCal])
        .expect("campaign");
    let campaign_path = tmp.path().join("cal.csv");
    std::fs::write(&campaign_path, measured.to_csv()).expect("write the campaign");
    let path = campaign_path.to_str().expect("a UTF-8 path");
    let calibrated = rpkm_json(
        &["calibrate", path, "--outlier-sigma", "0"],
        &tmp.path().join("cal.json"),
    );
    let diagnosed = rpkm_json(
        &["diagnose", path, "--model", "29"],
        &tmp.path().join("diag.json"),
    );
    let text = std::fs::read_to_string(&campaign_path).expect("campaign");
    let campaign = Campaign::parse(&text, path).expect("the foreign campaign parses");
    let node = calibrate_campaign(
        &campaign,
        &CalibratorOptions {
            start: Geometry {
                params: Params::nominal(),
                model: Model::M29,
                stiffness: rpkm_core::elastic::Stiffness::default(),
                source: "nominal".into(),
                effects: rpkm_nodes::node::effects::NodeEffects::default(),
            },
            validation_prefix: String::new(),
            selection: rpkm_nodes::node::calibrator::SelectionRule::Map,
            max_condition: 100.0,
            outlier_sigma: 0.0,
            noise: rpkm_core::noise::NoiseModel::default(),
            effects: None,
            weighting: rpkm_core::calib::Noise::ESTIMATE,
        },
    )
    .expect("the node calibrates");
    for (i, name) in NAMES.iter().enumerate() {
        let cli = value(&calibrated["parameters"], name);
        let diag = value(&diagnosed["parameters"], name);
        assert_eq!(
            cli.to_bits(),
            diag.to_bits(),
            "{name}: calibrate {cli} vs diagnose {diag}"
        );
        let k = node
            .parameters
            .names
            .iter()
            .position(|n| n == name)
            .unwrap_or_else(|| panic!("the node publishes {name}"));
        // the node publishes SI: its one conversion of mm, done here alike
        let si = if unit(i) == Unit::Mm { cli / 1e3 } else { cli };
        assert_eq!(
            node.parameters.values[k].to_bits(),
            si.to_bits(),
            "{name}: node {} vs calibrate {si}",
            node.parameters.values[k]
        );
    }
}
