//! Bags that `ros2 bag info/play` (Iron, Jazzy) open: every `metadata.yaml` rpkm writes, and
//! every reference bag in bags/, read by tests/cpp/rosbag2_metadata_check.cpp, which converts
//! each key rosbag2's storage layer requires for the file's version with yaml-cpp, as rosbag2
//! does (so a missing key fails with yaml-cpp's own "invalid node; first invalid key"), and
//! decodes the QoS profiles. A copy without `custom_data` must be refused: the checker bites.

mod bag_support;

use bag_support::{reference_bag, repo_root, rpkm, run_ok, scratch};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The checker compiled with g++ against yaml-cpp; `None` skips where yaml-cpp is missing,
/// except in CI (`RPKM_REQUIRE_PYTHON`, set by .ci/run, which installs libyaml-cpp-dev).
fn checker() -> Option<PathBuf> {
    let have = Path::new("/usr/include/yaml-cpp/yaml.h").is_file()
        && Command::new("g++").arg("--version").output().is_ok();
    if !have {
        assert!(
            std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
            "CI: g++ and libyaml-cpp-dev are required (.ci/run installs them)"
        );
        eprintln!("SKIPPED: g++ or yaml-cpp (libyaml-cpp-dev) not found");
        return None;
    }
    let out = scratch("mdcheck").join("rosbag2_metadata_check");
    let src = repo_root().join("tests/cpp/rosbag2_metadata_check.cpp");
    let status = Command::new("g++")
        .args(["-std=c++17", "-O1", "-o"])
        .arg(&out)
        .arg(&src)
        .arg("-lyaml-cpp")
        .status()
        .expect("g++ runs");
    assert!(status.success(), "the checker does not compile");
    Some(out)
}

fn check(checker: &Path, bag: &Path) -> (bool, String) {
    let out = Command::new(checker)
        .arg(bag)
        .output()
        .expect("checker runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).trim().to_owned(),
    )
}

#[test]
fn rosbag2_reads_the_metadata_of_every_bag_rpkm_writes() {
    let Some(checker) = checker() else { return };
    let dir = scratch("rosbag2-metadata");
    let fresh = dir.join("fresh");
    run_ok(
        rpkm()
            .args(["simulate", "--campaign", "lt", "--validation", "0", "--out"])
            .arg(&fresh),
    );
    let mut bags = vec![fresh.clone()];
    for name in ["calibration", "calibration_val", "preload_fault"] {
        bags.push(reference_bag(name));
    }
    for bag in &bags {
        let (ok, text) = check(&checker, bag);
        assert!(ok, "{}: {text}", bag.display());
        assert!(text.starts_with("ok version 8 topics "), "{text}");
    }
    let (_, fresh_text) = check(&checker, &fresh);
    assert!(fresh_text.ends_with(" files 1"), "{fresh_text}");

    // the checker refuses what rosbag2 refuses: the metadata without custom_data
    let stripped = dir.join("stripped");
    std::fs::create_dir_all(&stripped).expect("dir");
    let text = std::fs::read_to_string(fresh.join("metadata.yaml")).expect("metadata");
    let without: String = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("custom_data"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_ne!(without, text, "the fresh bag writes custom_data");
    std::fs::write(stripped.join("metadata.yaml"), without).expect("write");
    let (ok, text) = check(&checker, &stripped);
    assert!(
        !ok && text.contains("first invalid key") && text.contains("custom_data"),
        "{text}"
    );
}
