//! `rpkm calibrate` against an independent calibration: tests/python/scipy_calibration.py,
//! written from the spec (its own fgm, igm and assembly mode, scipy's least_squares with a
//! numerical Jacobian), fits the same self-calibration campaign of the twin with the same
//! unknowns and prior. Both must identify every parameter to within a third of rpkm's σ of
//! each other (the two weight the rows differently: rpkm by each follower's own noise
//! gain, estimated from the campaign; the script uniformly), and both must land within 3σ of
//! the twin's true machine.

use rpkm_core::campaign::Instrument;
use rpkm_twin::{Twin, TwinConfig};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The venv's Python with scipy; `None` skips, except under `RPKM_REQUIRE_PYTHON` (CI).
fn python() -> Option<PathBuf> {
    let py = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    let has_scipy = py.is_file()
        && Command::new(&py)
            .args(["-c", "import scipy"])
            .status()
            .is_ok_and(|s| s.success());
    if has_scipy {
        return Some(py);
    }
    assert!(
        std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
        "RPKM_REQUIRE_PYTHON is set but {} with scipy is missing",
        py.display()
    );
    eprintln!(
        "SKIPPED: {} with scipy not found (.ci/run installs it)",
        py.display()
    );
    None
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).expect("json written");
    serde_json::from_str(&text).expect("valid json")
}

#[test]
fn rpkm_and_an_independent_scipy_fit_identify_the_same_machine() {
    let Some(py) = python() else { return };
    let dir = std::env::temp_dir().join(format!("rpkm-scipy-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let mut twin = Twin::new(TwinConfig {
        seed: 11,
        ..Default::default()
    })
    .expect("twin");
    let campaign = twin
        .campaign(&[Instrument::SelfCal, Instrument::SelfCal])
        .expect("campaign");
    let truth = *twin.true_params();
    let csv = dir.join("self.csv");
    std::fs::write(&csv, campaign.to_csv()).expect("write");
    let (ours, theirs) = (dir.join("rpkm.json"), dir.join("scipy.json"));
    let out = Command::new(env!("CARGO_BIN_EXE_rpkm"))
        .arg("calibrate")
        .arg(&csv)
        .arg("--json")
        .arg(&ours)
        .output()
        .expect("rpkm runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/scipy_calibration.py");
    let out = Command::new(&py)
        .arg(&script)
        .arg(&csv)
        .arg("--json")
        .arg(&theirs)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (ours, theirs) = (json(&ours), json(&theirs));
    let identified = ours["identified"].as_array().expect("identified");
    assert_eq!(identified.len(), 29);
    for id in identified {
        let name = id["name"].as_str().expect("name");
        let (value, sigma) = (
            id["value"].as_f64().expect("value"),
            id["sigma"].as_f64().expect("sigma"),
        );
        let scipy = theirs[name].as_f64().expect("scipy has every parameter");
        let index = rpkm_core::params::index_of(name).expect("spec name");
        assert!(
            (value - scipy).abs() < sigma / 3.0,
            "{name}: rpkm {value:.5}, scipy {scipy:.5}, σ {sigma:.2e}"
        );
        for (who, v) in [("rpkm", value), ("scipy", scipy)] {
            let z = (v - truth[index]) / sigma;
            assert!(
                z.abs() < 3.0,
                "{name}: {who} {v:.5} is {z:.2}σ from the truth"
            );
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
