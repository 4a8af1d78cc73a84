//! SROS2 on the DDS side, as rcl reads it: `ROS_SECURITY_ENABLE` (`true` switches it on),
//! `ROS_SECURITY_STRATEGY` (`Enforce`, anything else is `Permissive`), `ROS_SECURITY_KEYSTORE`
//! and the node's enclave (`ROS_SECURITY_ENCLAVE_OVERRIDE` wins over the node's own). The
//! enclave's six files are checked here before the participant starts, so that a node that
//! cannot start says which file is missing or invalid instead of the DDS library's words.
//!
//! A node with credentials joins with DDS Security (RustDDS's builtin plugins: PKI-DH
//! authentication, permissions access control, AES-GCM-GMAC encryption). Without
//! credentials, `Enforce` refuses to start and `Permissive` runs unsecured (rcl's behaviour),
//! which the caller says aloud.

use std::path::{Path, PathBuf};

use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::{PKey, Private};
use openssl::stack::Stack;
use openssl::x509::store::X509StoreBuilder;
use openssl::x509::X509;

/// The enclave files rmw reads, in the order they are checked (rmw_dds_common's names).
pub const ENCLAVE_FILES: [&str; 6] = [
    "identity_ca.cert.pem",
    "cert.pem",
    "key.pem",
    "permissions_ca.cert.pem",
    "governance.p7s",
    "permissions.p7s",
];

/// What happens to a node whose enclave has no credentials.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Strategy {
    /// The node does not start.
    Enforce,
    /// The node runs without security.
    Permissive,
}

/// The security environment of a process.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SecurityEnv {
    /// `ROS_SECURITY_KEYSTORE`.
    pub keystore: PathBuf,
    /// `ROS_SECURITY_STRATEGY`.
    pub strategy: Strategy,
    /// `ROS_SECURITY_ENCLAVE_OVERRIDE`: the enclave of every node of the process.
    pub enclave_override: Option<String>,
}

/// An enclave's folder whose six files were found and checked.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Credentials {
    /// The enclave's name (`/rpkm/tcp_estimator`).
    pub enclave: String,
    /// Its folder: `<keystore>/enclaves/rpkm/tcp_estimator`.
    pub dir: PathBuf,
}

/// Why a node cannot join with security.
#[derive(Debug, thiserror::Error)]
pub enum SecurityError {
    /// Security is on but no keystore is named.
    #[error("ROS_SECURITY_ENABLE is true but ROS_SECURITY_KEYSTORE is not set")]
    NoKeystore,
    /// The enclave name is not an absolute ROS 2 namespace.
    #[error("enclave {enclave:?}: {reason}")]
    EnclaveName {
        /// The name given.
        enclave: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// An enclave file is missing under `Enforce`.
    #[error(
        "{}: missing (enclave {enclave}, ROS_SECURITY_STRATEGY=Enforce; create it with \
         `rpkm security enclave KEYSTORE {enclave}`)",
        path.display()
    )]
    Missing {
        /// The file.
        path: PathBuf,
        /// The enclave.
        enclave: String,
    },
    /// An enclave file is there but cannot be used.
    #[error("{}: invalid: {reason}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Reads the security environment: `None` unless `ROS_SECURITY_ENABLE` is `true`.
pub fn env() -> Result<Option<SecurityEnv>, SecurityError> {
    let var = |k: &str| std::env::var(k).ok().filter(|v| !v.trim().is_empty());
    if var("ROS_SECURITY_ENABLE").as_deref().map(str::trim) != Some("true") {
        return Ok(None);
    }
    let keystore = var("ROS_SECURITY_KEYSTORE").ok_or(SecurityError::NoKeystore)?;
    let strategy = match var("ROS_SECURITY_STRATEGY").as_deref().map(str::trim) {
        Some("Enforce") => Strategy::Enforce,
        _ => Strategy::Permissive,
    };
    Ok(Some(SecurityEnv {
        keystore: PathBuf::from(keystore),
        strategy,
        enclave_override: var("ROS_SECURITY_ENCLAVE_OVERRIDE"),
    }))
}

/// Why `name` is not an enclave name (an absolute ROS 2 namespace: `/`, then `/`-separated
/// parts of letters, digits and `_`, none starting with a digit), or `None`.
pub fn enclave_name_error(name: &str) -> Option<&'static str> {
    let Some(rest) = name.strip_prefix('/') else {
        return Some("expected an absolute name starting with `/`");
    };
    if rest.is_empty() {
        return None;
    }
    for part in rest.split('/') {
        if part.is_empty() {
            return Some("has an empty part (`//` or a trailing `/`)");
        }
        if part.starts_with(|c: char| c.is_ascii_digit()) {
            return Some("has a part starting with a digit");
        }
        if !part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Some("has a character other than a letter, a digit, `_` or `/`");
        }
    }
    None
}

/// The folder of `enclave` in `keystore`: `<keystore>/enclaves/<enclave>`.
pub fn enclave_dir(keystore: &Path, enclave: &str) -> Result<PathBuf, SecurityError> {
    if let Some(reason) = enclave_name_error(enclave) {
        return Err(SecurityError::EnclaveName {
            enclave: enclave.to_owned(),
            reason,
        });
    }
    let mut dir = keystore.join("enclaves");
    dir.extend(enclave.split('/').filter(|p| !p.is_empty()));
    Ok(dir)
}

/// The checked credentials of `enclave` (or the override), `None` where they are missing and
/// the strategy is `Permissive`. Files that exist are checked under both strategies: a
/// broken keystore is a mistake to fix, not a reason to run unsecured.
pub fn credentials(env: &SecurityEnv, enclave: &str) -> Result<Option<Credentials>, SecurityError> {
    let enclave = env.enclave_override.as_deref().unwrap_or(enclave);
    let dir = enclave_dir(&env.keystore, enclave)?;
    let missing = ENCLAVE_FILES
        .iter()
        .map(|f| dir.join(f))
        .find(|p| !p.is_file());
    if let Some(path) = missing {
        return match env.strategy {
            Strategy::Enforce => Err(SecurityError::Missing {
                path,
                enclave: enclave.to_owned(),
            }),
            Strategy::Permissive => Ok(None),
        };
    }
    check(&dir)?;
    Ok(Some(Credentials {
        enclave: enclave.to_owned(),
        dir,
    }))
}

fn invalid(path: &Path, reason: impl std::fmt::Display) -> SecurityError {
    SecurityError::Invalid {
        path: path.to_owned(),
        reason: reason.to_string(),
    }
}

fn read(path: &Path) -> Result<Vec<u8>, SecurityError> {
    std::fs::read(path).map_err(|e| invalid(path, e))
}

fn certificate(path: &Path) -> Result<X509, SecurityError> {
    X509::from_pem(&read(path)?).map_err(|e| invalid(path, format!("not a PEM certificate: {e}")))
}

/// The certificate chain, the key pair and both signed documents of an enclave folder.
fn check(dir: &Path) -> Result<(), SecurityError> {
    let identity_ca = certificate(&dir.join(ENCLAVE_FILES[0]))?;
    let cert_path = dir.join(ENCLAVE_FILES[1]);
    let cert = certificate(&cert_path)?;
    let ca_key = identity_ca
        .public_key()
        .map_err(|e| invalid(&dir.join(ENCLAVE_FILES[0]), e))?;
    if !cert.verify(&ca_key).unwrap_or(false) {
        return Err(invalid(
            &cert_path,
            format!("not signed by {}", ENCLAVE_FILES[0]),
        ));
    }
    check_dates(&cert_path, &cert)?;
    let key_path = dir.join(ENCLAVE_FILES[2]);
    let key: PKey<Private> = PKey::private_key_from_pem(&read(&key_path)?)
        .map_err(|e| invalid(&key_path, format!("not a PEM private key: {e}")))?;
    let cert_key = cert.public_key().map_err(|e| invalid(&cert_path, e))?;
    if !cert_key.public_eq(&key) {
        return Err(invalid(&key_path, "not the key of cert.pem"));
    }
    let permissions_ca = certificate(&dir.join(ENCLAVE_FILES[3]))?;
    for doc in [ENCLAVE_FILES[4], ENCLAVE_FILES[5]] {
        verify_signed(&dir.join(doc), &permissions_ca)?;
    }
    Ok(())
}

fn check_dates(path: &Path, cert: &X509) -> Result<(), SecurityError> {
    let now = openssl::asn1::Asn1Time::days_from_now(0).map_err(|e| invalid(path, e))?;
    if cert.not_before() > now {
        return Err(invalid(
            path,
            format!("not valid before {}", cert.not_before()),
        ));
    }
    if cert.not_after() < now {
        return Err(invalid(path, format!("expired on {}", cert.not_after())));
    }
    Ok(())
}

/// Verifies an S/MIME signed document against the permissions CA; returns what was signed
/// (with its MIME header where it was signed as text, as sros2 and `openssl smime -text` do).
pub fn verify_signed(path: &Path, ca: &X509) -> Result<Vec<u8>, SecurityError> {
    let bytes = read(path)?;
    let (pkcs7, content) =
        Pkcs7::from_smime(&bytes).map_err(|e| invalid(path, format!("not S/MIME: {e}")))?;
    let mut store = X509StoreBuilder::new().map_err(|e| invalid(path, e))?;
    store.add_cert(ca.clone()).map_err(|e| invalid(path, e))?;
    let store = store.build();
    let certs = Stack::new().map_err(|e| invalid(path, e))?;
    let mut out = Vec::new();
    pkcs7
        .verify(
            &certs,
            &store,
            content.as_deref(),
            Some(&mut out),
            Pkcs7Flags::empty(),
        )
        .map_err(|e| {
            invalid(
                path,
                format!("signature not verified by the permissions CA: {e}"),
            )
        })?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enclave_names_follow_ros_namespaces() {
        assert_eq!(enclave_name_error("/rpkm/tcp_estimator"), None);
        assert_eq!(enclave_name_error("/"), None);
        assert!(enclave_name_error("rpkm/x").is_some());
        assert!(enclave_name_error("/rpkm//x").is_some());
        assert!(enclave_name_error("/rpkm/x/").is_some());
        assert!(enclave_name_error("/rpkm/../x").is_some());
        assert!(enclave_name_error("/rpkm/2x").is_some());
        let dir = enclave_dir(Path::new("/k"), "/rpkm/tcp_estimator").expect("valid");
        assert_eq!(dir, Path::new("/k/enclaves/rpkm/tcp_estimator"));
    }

    #[test]
    fn a_missing_file_stops_enforce_and_lets_permissive_run_unsecured() {
        let keystore = std::env::temp_dir().join(format!("rpkm_sec_{}", std::process::id()));
        let mut env = SecurityEnv {
            keystore: keystore.clone(),
            strategy: Strategy::Enforce,
            enclave_override: None,
        };
        match credentials(&env, "/rpkm/ingest") {
            Err(SecurityError::Missing { path, enclave }) => {
                assert_eq!(
                    path,
                    keystore.join("enclaves/rpkm/ingest/identity_ca.cert.pem")
                );
                assert_eq!(enclave, "/rpkm/ingest");
            }
            other => panic!("expected Missing, got {other:?}"),
        }
        env.strategy = Strategy::Permissive;
        assert_eq!(credentials(&env, "/rpkm/ingest").ok(), Some(None));
        env.enclave_override = Some("/cell".into());
        env.strategy = Strategy::Enforce;
        match credentials(&env, "/rpkm/ingest") {
            Err(SecurityError::Missing { enclave, .. }) => assert_eq!(enclave, "/cell"),
            other => panic!("expected Missing, got {other:?}"),
        }
    }
}
