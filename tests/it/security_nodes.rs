//! SROS2's environment as rcl reads it, honoured by the nodes and by `rpkm record`: under
//! `Enforce` a program without valid credentials does not start and names the file (exit 2,
//! so that `rpkm launch` does not restart it); under `Permissive` it runs without security
//! and says so; with credentials it joins.

use crate::node_support::{rpkm, TempDir};
use crate::security_support::{env, keystore, security};

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const DOMAIN: &str = "91";

/// `rpkm ARGS` with `envs`, until it exits (at most 60 s): (exit code, stderr).
fn run(args: &[&str], envs: &[(String, String)]) -> (Option<i32>, String) {
    let mut child = Command::new(rpkm())
        .args(args)
        .envs(envs.iter().map(|(k, v)| (k, v)))
        .env("ROS_DOMAIN_ID", DOMAIN)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start rpkm");
    let stderr = child.stderr.take().expect("piped");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let text: Vec<String> = BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
            .collect();
        let _ = tx.send(text.join("\n"));
    });
    let text = rx
        .recv_timeout(Duration::from_secs(60))
        .unwrap_or_else(|_| {
            let _ = child.kill();
            panic!("rpkm {args:?} did not exit within 60 s")
        });
    let status = child.wait().expect("wait");
    (status.code(), text)
}

/// `rpkm ARGS` with `envs` until its stderr has a line with `needle` (then SIGTERM), or it
/// exits: whether the line came, and stderr so far.
fn starts(args: &[&str], envs: &[(String, String)], needle: &str) -> (bool, String) {
    let mut child = Command::new(rpkm())
        .args(args)
        .envs(envs.iter().map(|(k, v)| (k, v)))
        .env("ROS_DOMAIN_ID", DOMAIN)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start rpkm");
    let stderr = child.stderr.take().expect("piped");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut seen = Vec::new();
    let mut found = false;
    while let Ok(line) = rx.recv_timeout(Duration::from_secs(60)) {
        found = line.contains(needle);
        seen.push(line);
        if found {
            break;
        }
    }
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let _ = child.wait();
    (found, seen.join("\n"))
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

#[test]
fn enforce_refuses_a_node_without_credentials_naming_the_file() {
    let tmp = TempDir::new("sec_enforce");
    // a keystore without enclaves
    let ks = tmp.path("keys");
    let out = security(&["keystore", path(&ks)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let enforce = env(&ks, "Enforce");
    let node = ["node", "tcp_estimator", "--backend", "dds"];
    let (code, err) = run(&node, &enforce);
    assert_eq!(code, Some(2), "{err}");
    let missing = ks.join("enclaves/rpkm/tcp_estimator/identity_ca.cert.pem");
    assert!(
        err.contains(&format!("{}: missing", missing.display())),
        "{err}"
    );
    // the recorder too, in its own enclave
    let (code, err) = run(&["record", "--backend", "dds", "--duration", "1"], &enforce);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("enclaves/rpkm/record/identity_ca.cert.pem: missing"),
        "{err}"
    );

    // Permissive: the node runs, unsecured, and says so
    let (started, err) = starts(&node, &env(&ks, "Permissive"), "estimating with");
    assert!(started, "{err}");
    assert!(err.contains("joining DDS without security"), "{err}");
}

#[test]
fn a_tampered_document_or_a_foreign_enclave_is_named_and_refused() {
    let tmp = TempDir::new("sec_tamper");
    let ks = keystore(&tmp.0, &[]);
    let enforce = env(&ks, "Enforce");
    let node = ["node", "preload_monitor", "--backend", "dds"];

    // one granted topic renamed inside the signed text: the signature no longer holds
    let p7s = ks.join("enclaves/rpkm/preload_monitor/permissions.p7s");
    let original = std::fs::read_to_string(&p7s).expect("p7s");
    let forged = original.replacen("rt/rpkm/preload_status", "rt/rpkm/tcp_estimate_", 1);
    assert_ne!(forged, original);
    std::fs::write(&p7s, forged).expect("write");
    let (code, err) = run(&node, &enforce);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!(
            "{}: invalid: signature not verified",
            p7s.display()
        )),
        "{err}"
    );
    std::fs::write(&p7s, original).expect("restore");

    // another keystore's identity in this one's enclave: not signed by this CA
    let other = TempDir::new("sec_tamper_other");
    let other_ks = keystore(&other.0, &[]);
    let cert = ks.join("enclaves/rpkm/preload_monitor/cert.pem");
    let own_cert = std::fs::read(&cert).expect("cert");
    std::fs::copy(
        other_ks.join("enclaves/rpkm/preload_monitor/cert.pem"),
        &cert,
    )
    .expect("copy");
    let (code, err) = run(&node, &enforce);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(&format!(
            "{}: invalid: not signed by identity_ca.cert.pem",
            cert.display()
        )),
        "{err}"
    );
    std::fs::write(&cert, own_cert).expect("restore");

    // the enclave from the parameter and from --ros-args (which wins)
    let (code, err) = run(
        &[&node[..], &["--param", "enclave=/cell/monitor_a"]].concat(),
        &enforce,
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("enclaves/cell/monitor_a/identity_ca.cert.pem: missing"),
        "{err}"
    );
    let (code, err) = run(
        &[
            &node[..],
            &[
                "--param",
                "enclave=/cell/monitor_a",
                "--ros-args",
                "--enclave",
                "/cell/b",
            ],
        ]
        .concat(),
        &enforce,
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("enclaves/cell/b/identity_ca.cert.pem: missing"),
        "{err}"
    );

    // with its own, intact credentials the node joins with security and runs
    let (started, err) = starts(&node, &enforce, "monitoring with");
    assert!(started, "{err}");
    assert!(!err.contains("without security"), "{err}");
}
