//! `rpkm security keystore|enclave|permissions` write sros2's layout, and the openssl
//! command line (an independent implementation of X.509 and S/MIME) accepts what they
//! wrote: each enclave's certificate chains to the identity CA, governance and permissions
//! are signed by the permissions CA, and a document signed by another keystore is refused.

use crate::node_support::TempDir;
use crate::security_support::{keystore, openssl, openssl_run, security};

use std::os::unix::fs::PermissionsExt;
use std::path::Path;

const PROGRAMS: [&str; 8] = [
    "ingest",
    "tcp_estimator",
    "calibrator",
    "preload_monitor",
    "record",
    "replay",
    "monitor",
    "launch",
];

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// What `openssl smime -verify` gives back from a signed document, or its error.
fn smime_content(p7s: &Path, ca: &Path) -> Result<String, String> {
    let (ok, out, err) = openssl_run(&[
        "smime",
        "-verify",
        "-text",
        "-in",
        path(p7s),
        "-CAfile",
        path(ca),
    ]);
    if ok {
        Ok(out.replace("\r\n", "\n"))
    } else {
        Err(err)
    }
}

#[test]
fn every_enclave_chains_to_the_keystores_ca_and_its_documents_verify() {
    let Some(()) = openssl() else { return };
    let tmp = TempDir::new("sec_ks");
    let ks = keystore(&tmp.0, &[]);
    let identity_ca = ks.join("public/identity_ca.cert.pem");
    let permissions_ca = ks.join("public/permissions_ca.cert.pem");
    let governance = std::fs::read_to_string(ks.join("enclaves/governance.xml")).expect("xml");
    assert_eq!(
        smime_content(&ks.join("enclaves/governance.p7s"), &permissions_ca),
        Ok(governance.clone())
    );
    for program in PROGRAMS {
        let dir = ks.join("enclaves/rpkm").join(program);
        let cert = dir.join("cert.pem");
        let (ok, out, err) = openssl_run(&["verify", "-CAfile", path(&identity_ca), path(&cert)]);
        assert!(ok && out.trim().ends_with(": OK"), "{program}: {out} {err}");
        let (_, subject, _) = openssl_run(&["x509", "-noout", "-subject", "-in", path(&cert)]);
        assert_eq!(subject.trim(), format!("subject=CN = /rpkm/{program}"));
        // the key is the certificate's
        let (_, from_key, _) = openssl_run(&["pkey", "-pubout", "-in", path(&dir.join("key.pem"))]);
        let (_, from_cert, _) = openssl_run(&["x509", "-noout", "-pubkey", "-in", path(&cert)]);
        assert!(from_key.contains("BEGIN PUBLIC KEY"), "{from_key}");
        assert_eq!(
            from_key, from_cert,
            "{program}: key.pem is not cert.pem's key"
        );
        let mode = std::fs::metadata(dir.join("key.pem"))
            .expect("key")
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600, "{program}: key.pem mode {mode:o}");
        let xml = std::fs::read_to_string(dir.join("permissions.xml")).expect("xml");
        assert!(xml.contains(&format!("<subject_name>CN=/rpkm/{program}</subject_name>")));
        assert_eq!(
            smime_content(
                &dir.join("permissions.p7s"),
                &dir.join("permissions_ca.cert.pem")
            ),
            Ok(xml)
        );
        // the enclave's governance is the keystore's (a link, as sros2 lays it out)
        assert_eq!(
            smime_content(&dir.join("governance.p7s"), &permissions_ca),
            Ok(governance.clone())
        );
    }
    // A document of another keystore does not verify against this one's CA.
    let other = TempDir::new("sec_ks_other");
    let other_ks = keystore(&other.0, &[]);
    let foreign = other_ks.join("enclaves/rpkm/tcp_estimator/permissions.p7s");
    let refused = smime_content(&foreign, &permissions_ca);
    assert!(
        refused.is_err(),
        "a foreign signature verified: {refused:?}"
    );
}

#[test]
fn the_governance_protects_and_each_grant_names_only_its_programs_topics() {
    let tmp = TempDir::new("sec_grant");
    let ks = keystore(&tmp.0, &[]);
    let governance = std::fs::read_to_string(ks.join("enclaves/governance.xml")).expect("xml");
    for rule in [
        "<allow_unauthenticated_participants>false</allow_unauthenticated_participants>",
        "<enable_join_access_control>true</enable_join_access_control>",
        "<discovery_protection_kind>ENCRYPT</discovery_protection_kind>",
        "<liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>",
        "<rtps_protection_kind>ENCRYPT</rtps_protection_kind>",
        "<metadata_protection_kind>ENCRYPT</metadata_protection_kind>",
    ] {
        assert!(governance.contains(rule), "governance lacks {rule}");
    }
    let permissions = |program: &str| {
        let xml = std::fs::read_to_string(
            ks.join("enclaves/rpkm")
                .join(program)
                .join("permissions.xml"),
        )
        .expect("permissions.xml");
        let section = |tag: &str| {
            let open = xml.find(&format!("<{tag}>")).expect(tag);
            let close = xml.find(&format!("</{tag}>")).expect(tag);
            xml[open..close].to_owned()
        };
        (section("publish"), section("subscribe"))
    };
    let (publish, subscribe) = permissions("tcp_estimator");
    assert!(publish.contains("<topic>rt/rpkm/tcp_estimate</topic>"));
    assert!(
        !publish.contains("rt/rpkm/campaign_info"),
        "the end marker is ingest's"
    );
    assert!(subscribe.contains("<topic>rt/rpkm/actuator_state</topic>"));
    assert!(subscribe.contains("<topic>rq/rpkm/tcp_estimator/set_parametersRequest</topic>"));
    let (publish, _) = permissions("ingest");
    assert!(publish.contains("<topic>rt/rpkm/campaign_info</topic>"));
    assert!(!publish.contains("rt/rpkm/tcp_estimate"));
    let (publish, subscribe) = permissions("record");
    assert!(subscribe.contains("<topic>rt/rpkm/tcp_estimate</topic>"));
    assert!(
        !publish.contains("rt/rpkm/"),
        "the recorder publishes no rpkm topic: {publish}"
    );
    // --namespace moves the set's names
    let s = path(&ks);
    let out = security(&[
        "permissions",
        s,
        "/rpkm/preload_monitor",
        "--namespace",
        "/machine_a",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (publish, _) = permissions("preload_monitor");
    assert!(
        publish.contains("<topic>rt/machine_a/preload_status</topic>"),
        "{publish}"
    );
    assert!(!publish.contains("rt/rpkm/preload_status"));
}

#[test]
fn a_missing_keystore_an_unknown_program_or_a_bad_name_exit_2_saying_which() {
    let tmp = TempDir::new("sec_bad");
    let nowhere = tmp.path("nowhere");
    let out = security(&["enclave", path(&nowhere), "/rpkm/tcp_estimator"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("not a keystore") && err.contains("public/identity_ca.cert.pem"),
        "{err}"
    );

    let ks = keystore(&tmp.0, &[]);
    let s = path(&ks);
    let ca = std::fs::read(ks.join("public/ca.cert.pem")).expect("ca");
    let again = security(&["keystore", s]);
    assert!(again.status.success());
    assert_eq!(
        std::fs::read(ks.join("public/ca.cert.pem")).expect("ca"),
        ca,
        "CA replaced"
    );

    for (args, expected) in [
        (
            vec!["enclave", s, "/rpkm/conveyor"],
            "no default permissions for \"conveyor\"",
        ),
        (
            vec!["enclave", s, "rpkm/ingest"],
            "expected an absolute name",
        ),
        (
            vec!["permissions", s, "/cell/ingest"],
            "enclaves/cell/ingest/cert.pem is missing",
        ),
    ] {
        let out = security(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(expected), "{args:?}: {err}");
    }
    // an enclave of any name takes a program's permissions with --node
    let out = security(&["enclave", s, "/cell/peer", "--node", "monitor"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(ks.join("enclaves/cell/peer/permissions.p7s").is_file());
}
