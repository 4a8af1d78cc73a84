//! Shared by the security tests: a keystore made by `rpkm security`, the environment that
//! switches SROS2 on, and the openssl command line as the independent checker.
#![allow(dead_code)] // each test file uses a part

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::node_support::rpkm;

/// `rpkm security ARGS...`, its output.
pub fn security(args: &[&str]) -> Output {
    Command::new(rpkm())
        .arg("security")
        .args(args)
        .output()
        .expect("rpkm security runs")
}

/// A keystore in `dir` with every program's default enclave (`--all`), and `extra`
/// enclaves as (name, program).
pub fn keystore(dir: &Path, extra: &[(&str, &str)]) -> PathBuf {
    let ks = dir.join("keys");
    let s = ks.to_str().expect("utf-8 path");
    for args in [vec!["keystore", s], vec!["enclave", s, "--all"]] {
        let out = security(&args);
        assert!(
            out.status.success(),
            "rpkm security {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    for (name, program) in extra {
        let out = security(&["enclave", s, name, "--node", program]);
        assert!(
            out.status.success(),
            "rpkm security enclave {name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    ks
}

/// The environment rcl reads: security on, `strategy`, the keystore.
pub fn env(keystore: &Path, strategy: &str) -> Vec<(String, String)> {
    vec![
        ("ROS_SECURITY_ENABLE".into(), "true".into()),
        ("ROS_SECURITY_STRATEGY".into(), strategy.into()),
        (
            "ROS_SECURITY_KEYSTORE".into(),
            keystore.to_str().expect("utf-8 path").into(),
        ),
    ]
}

/// Whether `what` is there (`have`); a missing tool skips with a word, except in CI
/// (`RPKM_REQUIRE_PYTHON`, set by .ci/run, which installs it).
pub fn required(have: bool, what: &str) -> bool {
    if !have {
        assert!(
            std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
            "CI: {what} is required (.ci/run installs it)"
        );
        eprintln!("SKIPPED: {what} not found");
    }
    have
}

/// Whether the openssl command line is there; `None` skips with a word, except in CI.
pub fn openssl() -> Option<()> {
    if Command::new("openssl").arg("version").output().is_ok() {
        return Some(());
    }
    assert!(
        std::env::var_os("RPKM_REQUIRE_PYTHON").is_none(),
        "CI: the openssl command is required (.ci/run installs it)"
    );
    eprintln!("SKIPPED: openssl not found");
    None
}

/// `openssl ARGS...`: (success, stdout, stderr).
pub fn openssl_run(args: &[&str]) -> (bool, String, String) {
    let out = Command::new("openssl")
        .args(args)
        .output()
        .expect("openssl runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
