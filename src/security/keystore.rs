//! An SROS2 keystore written as sros2 writes it, without a ROS installation:
//!
//! ```text
//! DIR/public/ca.cert.pem                 the keystore's CA (identity and permissions CA)
//! DIR/public/{identity,permissions}_ca.cert.pem -> ca.cert.pem
//! DIR/private/ca.key.pem                 its key (keep it off the machines)
//! DIR/private/{identity,permissions}_ca.key.pem -> ca.key.pem
//! DIR/enclaves/governance.xml, governance.p7s   signed by the permissions CA
//! DIR/enclaves/<enclave>/cert.pem, key.pem      the enclave's identity (CN=<enclave>)
//! DIR/enclaves/<enclave>/permissions.xml, permissions.p7s
//! DIR/enclaves/<enclave>/{identity_ca.cert.pem, permissions_ca.cert.pem, governance.p7s}
//!                                        -> the keystore's (relative links)
//! ```
//!
//! Keys are ECDSA on prime256v1 (PKCS#8 PEM, unencrypted, as rmw reads them), certificates
//! X.509 v3 signed with SHA-256, documents S/MIME clear-signed (`multipart/signed`, text), all
//! by OpenSSL through the `openssl` crate: no cryptography of our own.

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use openssl::asn1::Asn1Time;
use openssl::bn::{BigNum, MsbOption};
use openssl::ec::{EcGroup, EcKey};
use openssl::hash::MessageDigest;
use openssl::nid::Nid;
use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::{PKey, Private};
use openssl::stack::Stack;
use openssl::x509::extension::BasicConstraints;
use openssl::x509::{X509Name, X509};

use super::policy::{self, Grant, Validity};

/// Days a certificate and a grant are valid (sros2's ten years).
const VALID_DAYS: u32 = 3650;
/// Subject of the keystore's CA.
const CA_NAME: &str = "rpkm keystore CA";

/// Why the keystore cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum KeystoreError {
    /// A file or folder could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
    /// OpenSSL refused an operation.
    #[error("{what}: {source}")]
    OpenSsl {
        /// What was being made.
        what: String,
        /// OpenSSL's error stack.
        #[source]
        source: openssl::error::ErrorStack,
    },
    /// The folder is not a keystore (a file of it is missing).
    #[error(
        "{}: not a keystore: {} is missing (create one with `rpkm security keystore DIR`)",
        root.display(), missing.display()
    )]
    NotAKeystore {
        /// The folder given.
        root: PathBuf,
        /// The first file not found.
        missing: PathBuf,
    },
    /// The enclave has no identity yet.
    #[error(
        "enclave {enclave}: {} is missing (create it with `rpkm security enclave {} {enclave}`)",
        missing.display(), root.display()
    )]
    NoEnclave {
        /// The keystore.
        root: PathBuf,
        /// The enclave.
        enclave: String,
        /// The file not found.
        missing: PathBuf,
    },
    /// The enclave's name or program cannot be used.
    #[error("enclave {enclave:?}: {reason}")]
    Enclave {
        /// The name given.
        enclave: String,
        /// Why.
        reason: String,
    },
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> KeystoreError + '_ {
    move |source| KeystoreError::Io {
        path: path.to_owned(),
        source,
    }
}

fn ssl(what: &str) -> impl FnOnce(openssl::error::ErrorStack) -> KeystoreError + '_ {
    move |source| KeystoreError::OpenSsl {
        what: what.to_owned(),
        source,
    }
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), KeystoreError> {
    std::fs::write(path, bytes).map_err(io(path))
}

/// Writes a private key readable by its owner only.
fn write_private(path: &Path, bytes: &[u8]) -> Result<(), KeystoreError> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)
        .map_err(io(path))?;
    f.write_all(bytes).map_err(io(path))
}

fn mkdir(path: &Path) -> Result<(), KeystoreError> {
    std::fs::create_dir_all(path).map_err(io(path))
}

/// `link -> target` (relative), replacing an older link of that name.
fn symlink(target: &Path, link: &Path) -> Result<(), KeystoreError> {
    if link.symlink_metadata().is_ok() {
        std::fs::remove_file(link).map_err(io(link))?;
    }
    std::os::unix::fs::symlink(target, link).map_err(io(link))
}

fn new_key() -> Result<PKey<Private>, KeystoreError> {
    let group = EcGroup::from_curve_name(Nid::X9_62_PRIME256V1).map_err(ssl("EC group"))?;
    let ec = EcKey::generate(&group).map_err(ssl("EC key"))?;
    PKey::from_ec_key(ec).map_err(ssl("EC key"))
}

fn name(cn: &str) -> Result<X509Name, KeystoreError> {
    let mut b = X509Name::builder().map_err(ssl("X.509 name"))?;
    b.append_entry_by_nid(Nid::COMMONNAME, cn)
        .map_err(ssl("X.509 name"))?;
    Ok(b.build())
}

/// A certificate of `subject` for `key`, signed by `issuer` (itself where `None`).
fn certificate(
    subject: &str,
    key: &PKey<Private>,
    issuer: Option<(&X509, &PKey<Private>)>,
) -> Result<X509, KeystoreError> {
    let what = format!("certificate of {subject}");
    let e = |source| KeystoreError::OpenSsl {
        what: what.clone(),
        source,
    };
    let mut b = X509::builder().map_err(e)?;
    b.set_version(2).map_err(e)?;
    let mut serial = BigNum::new().map_err(e)?;
    serial.rand(159, MsbOption::MAYBE_ZERO, false).map_err(e)?;
    let serial = serial.to_asn1_integer().map_err(e)?;
    b.set_serial_number(&serial).map_err(e)?;
    let subject_name = name(subject)?;
    b.set_subject_name(&subject_name).map_err(e)?;
    let not_before = Asn1Time::days_from_now(0).map_err(e)?;
    let not_after = Asn1Time::days_from_now(VALID_DAYS).map_err(e)?;
    b.set_not_before(&not_before).map_err(e)?;
    b.set_not_after(&not_after).map_err(e)?;
    b.set_pubkey(key).map_err(e)?;
    let constraints = match issuer {
        None => BasicConstraints::new().critical().ca().pathlen(1).build(),
        Some(_) => BasicConstraints::new().critical().build(),
    }
    .map_err(e)?;
    b.append_extension(constraints).map_err(e)?;
    let (issuer_name, signer) = match issuer {
        Some((cert, key)) => (cert.subject_name().to_owned().map_err(e)?, key),
        None => (subject_name, key),
    };
    b.set_issuer_name(&issuer_name).map_err(e)?;
    b.sign(signer, MessageDigest::sha256()).map_err(e)?;
    Ok(b.build())
}

/// `content` S/MIME clear-signed (text) by the CA, as `openssl smime -sign -text` does.
fn sign(ca: &Ca, content: &[u8], what: &str) -> Result<Vec<u8>, KeystoreError> {
    let flags = Pkcs7Flags::DETACHED | Pkcs7Flags::TEXT;
    let certs = Stack::new().map_err(ssl(what))?;
    let p7 = Pkcs7::sign(&ca.cert, &ca.key, &certs, content, flags).map_err(ssl(what))?;
    p7.to_smime(content, flags).map_err(ssl(what))
}

/// The keystore's CA: certificate and key.
struct Ca {
    cert: X509,
    key: PKey<Private>,
}

/// An SROS2 keystore folder.
#[derive(Debug, Clone)]
pub struct Keystore {
    root: PathBuf,
}

/// What [`Keystore::create`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Created {
    /// A new CA and governance.
    New,
    /// The folder already held a keystore: left as it was.
    Existing,
}

impl Keystore {
    fn public(&self) -> PathBuf {
        self.root.join("public")
    }
    fn private(&self) -> PathBuf {
        self.root.join("private")
    }
    fn enclaves(&self) -> PathBuf {
        self.root.join("enclaves")
    }
    /// The files a keystore must have.
    fn required(&self) -> [PathBuf; 5] {
        [
            self.public().join("identity_ca.cert.pem"),
            self.public().join("permissions_ca.cert.pem"),
            self.private().join("identity_ca.key.pem"),
            self.private().join("permissions_ca.key.pem"),
            self.enclaves().join("governance.p7s"),
        ]
    }

    /// Creates a keystore in `root` (CA, governance); an existing keystore is kept.
    pub fn create(root: &Path) -> Result<(Self, Created), KeystoreError> {
        let ks = Self {
            root: root.to_owned(),
        };
        if ks.required().iter().all(|p| p.is_file()) {
            return Ok((ks, Created::Existing));
        }
        for dir in [ks.public(), ks.private(), ks.enclaves()] {
            mkdir(&dir)?;
        }
        let key = new_key()?;
        let cert = certificate(CA_NAME, &key, None)?;
        let pem = cert.to_pem().map_err(ssl("CA certificate"))?;
        write(&ks.public().join("ca.cert.pem"), &pem)?;
        let key_pem = key.private_key_to_pem_pkcs8().map_err(ssl("CA key"))?;
        write_private(&ks.private().join("ca.key.pem"), &key_pem)?;
        for role in ["identity_ca", "permissions_ca"] {
            symlink(
                Path::new("ca.cert.pem"),
                &ks.public().join(format!("{role}.cert.pem")),
            )?;
            symlink(
                Path::new("ca.key.pem"),
                &ks.private().join(format!("{role}.key.pem")),
            )?;
        }
        let governance = policy::governance_xml();
        write(&ks.enclaves().join("governance.xml"), governance.as_bytes())?;
        let ca = Ca { cert, key };
        let signed = sign(&ca, governance.as_bytes(), "signing governance.xml")?;
        write(&ks.enclaves().join("governance.p7s"), &signed)?;
        Ok((ks, Created::New))
    }

    /// The keystore in `root`; an error names the first missing file.
    pub fn open(root: &Path) -> Result<Self, KeystoreError> {
        let ks = Self {
            root: root.to_owned(),
        };
        if let Some(missing) = ks.required().into_iter().find(|p| !p.is_file()) {
            return Err(KeystoreError::NotAKeystore {
                root: root.to_owned(),
                missing,
            });
        }
        Ok(ks)
    }

    fn ca(&self, role: &str) -> Result<Ca, KeystoreError> {
        let cert_path = self.public().join(format!("{role}.cert.pem"));
        let key_path = self.private().join(format!("{role}.key.pem"));
        let cert_pem = std::fs::read(&cert_path).map_err(io(&cert_path))?;
        let key_pem = std::fs::read(&key_path).map_err(io(&key_path))?;
        Ok(Ca {
            cert: X509::from_pem(&cert_pem).map_err(ssl(&cert_path.display().to_string()))?,
            key: PKey::private_key_from_pem(&key_pem)
                .map_err(ssl(&key_path.display().to_string()))?,
        })
    }

    /// The folder of `enclave`.
    pub fn enclave_dir(&self, enclave: &str) -> Result<PathBuf, KeystoreError> {
        rpkm_transport::security::enclave_dir(&self.root, enclave).map_err(|e| {
            KeystoreError::Enclave {
                enclave: enclave.to_owned(),
                reason: e.to_string(),
            }
        })
    }

    /// Creates `enclave`: its identity (kept where it exists), the links to the keystore's
    /// CA certificates and governance, and its permissions from `grant`.
    pub fn create_enclave(&self, enclave: &str, grant: &Grant) -> Result<PathBuf, KeystoreError> {
        let dir = self.enclave_dir(enclave)?;
        mkdir(&dir)?;
        let up = "../".repeat(enclave.split('/').filter(|p| !p.is_empty()).count() + 1);
        for cert in ["identity_ca.cert.pem", "permissions_ca.cert.pem"] {
            symlink(&Path::new(&up).join("public").join(cert), &dir.join(cert))?;
        }
        symlink(
            &Path::new(&up).join("enclaves/governance.p7s"),
            &dir.join("governance.p7s"),
        )?;
        let (cert_path, key_path) = (dir.join("cert.pem"), dir.join("key.pem"));
        if !cert_path.is_file() || !key_path.is_file() {
            let ca = self.ca("identity_ca")?;
            let key = new_key()?;
            let cert = certificate(enclave, &key, Some((&ca.cert, &ca.key)))?;
            let pem = cert.to_pem().map_err(ssl("enclave certificate"))?;
            write(&cert_path, &pem)?;
            let key_pem = key.private_key_to_pem_pkcs8().map_err(ssl("enclave key"))?;
            write_private(&key_path, &key_pem)?;
        }
        self.write_permissions(enclave, grant)?;
        Ok(dir)
    }

    /// Writes and signs the permissions of an existing `enclave` from `grant`.
    pub fn write_permissions(
        &self,
        enclave: &str,
        grant: &Grant,
    ) -> Result<PathBuf, KeystoreError> {
        let dir = self.enclave_dir(enclave)?;
        let cert = dir.join("cert.pem");
        if !cert.is_file() {
            return Err(KeystoreError::NoEnclave {
                root: self.root.clone(),
                enclave: enclave.to_owned(),
                missing: cert,
            });
        }
        let xml = policy::permissions_xml(enclave, grant, &validity_from_now());
        let path = dir.join("permissions.xml");
        write(&path, xml.as_bytes())?;
        let ca = self.ca("permissions_ca")?;
        let signed = sign(&ca, xml.as_bytes(), "signing permissions.xml")?;
        let p7s = dir.join("permissions.p7s");
        write(&p7s, &signed)?;
        Ok(p7s)
    }
}

/// A grant's validity: from now (to the second, UTC) for [`VALID_DAYS`].
fn validity_from_now() -> Validity {
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let later = now + u64::from(VALID_DAYS) * 86_400;
    Validity {
        not_before: utc(now),
        not_after: utc(later),
    }
}

/// `YYYY-MM-DDTHH:MM:SS` of seconds since 1970 (UTC): the proleptic Gregorian calendar
/// from a day count (H. Hinnant's `civil_from_days`).
fn utc(secs: u64) -> String {
    let days = secs / 86_400;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + u64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates_match_known_instants() {
        assert_eq!(utc(0), "1970-01-01T00:00:00");
        // 2000-02-29 12:34:56 UTC, a leap day of a century leap year
        assert_eq!(utc(951_827_696), "2000-02-29T12:34:56");
        // 2026-11-26 00:00:00 UTC
        assert_eq!(utc(1_795_651_200), "2026-11-26T00:00:00");
    }
}
