//! `[server.tls]`: the certificate and key rackd serves HTTPS and WSS with, and what makes
//! a pair of PEM files a usable one. The serving side (the handshake, the reload when the
//! files change) is `app::serve::tls`; the check here is what `check-config` and the
//! start run, and what every reload runs on the new files.
//!
//! - `cert_file` holds the certificate chain, the server's own certificate first, then any
//!   intermediates (what a CA or the site's tooling writes as `fullchain.pem`).
//! - `key_file` holds its private key: PKCS#8 (`BEGIN PRIVATE KEY`), PKCS#1 RSA
//!   (`BEGIN RSA PRIVATE KEY`) or SEC1 EC (`BEGIN EC PRIVATE KEY`). It must match the first
//!   certificate: a rotation caught half-way (new certificate, old key) is refused, not
//!   served.
//! - Relative paths are from the working directory, as `database.path`.
//! - rustls with the ring provider only (no OpenSSL, no aws-lc-rs), TLS 1.2 and 1.3 with
//!   rustls' safe defaults.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use rustls::sign::CertifiedKey;
use serde::{Deserialize, Serialize};

/// What the `certificate` alarm with code 0 (the certificate served expires within 14 days)
/// asks.
pub const EXPIRING_ACTION: &str = "Install a renewed certificate and its key at server.tls.cert_file and \
     key_file (written beside and renamed into place): rackd serves it to new connections within \
     seconds, without a restart, and this alarm clears.";

/// What the `certificate` alarm with code 1 (the files changed but do not load) asks.
pub const REFUSED_ACTION: &str = "Put a certificate chain and its own private key (PEM) at \
     server.tls.cert_file and key_file, as `rackd check-config` takes them: the next read that loads \
     is served and clears this alarm. Until then the previous certificate is served.";

/// `[server.tls]`: HTTPS and WSS on `server.listen` (no plain HTTP beside it).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TlsConfig {
    /// PEM certificate chain, the server's certificate first.
    pub cert_file: PathBuf,
    /// PEM private key (PKCS#8, PKCS#1 RSA or SEC1 EC) of the first certificate.
    pub key_file: PathBuf,
    /// How often the files are read again to pick up a rotated certificate. Not a key of
    /// the file (every few seconds is right for any site); the tests shorten it.
    #[serde(skip, default = "reload_every")]
    pub reload_every: Duration,
}

fn reload_every() -> Duration {
    Duration::from_secs(5)
}

impl TlsConfig {
    /// A pair of files, reloaded at the usual pace.
    pub fn new(cert_file: impl Into<PathBuf>, key_file: impl Into<PathBuf>) -> TlsConfig {
        TlsConfig { cert_file: cert_file.into(), key_file: key_file.into(), reload_every: reload_every() }
    }

    /// Reads both files as they are now.
    pub fn read(&self) -> Result<Pem, TlsError> {
        let read = |file: TlsFile, path: &Path| {
            std::fs::read(path).map_err(|e| TlsError::Read {
                file,
                path: path.to_owned(),
                message: e.to_string(),
            })
        };
        Ok(Pem { cert: read(TlsFile::Cert, &self.cert_file)?, key: read(TlsFile::Key, &self.key_file)? })
    }

    /// Reads and checks both files: the certificate and key to serve.
    pub fn load(&self) -> Result<Arc<CertifiedKey>, TlsError> {
        self.read()?.certified_key(self)
    }
}

/// The two files' contents, as read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pem {
    /// `cert_file`'s bytes.
    pub cert: Vec<u8>,
    /// `key_file`'s bytes.
    pub key: Vec<u8>,
}

impl Pem {
    /// The certificate chain and its key, checked against each other; `files` only names
    /// the files in errors.
    pub fn certified_key(&self, files: &TlsConfig) -> Result<Arc<CertifiedKey>, TlsError> {
        let bad = |file: TlsFile, message: String| {
            let path = match file {
                TlsFile::Cert => files.cert_file.clone(),
                TlsFile::Key => files.key_file.clone(),
            };
            TlsError::Bad { file, path, message }
        };
        let chain = CertificateDer::pem_slice_iter(&self.cert)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| bad(TlsFile::Cert, format!("not a PEM certificate chain: {e}")))?;
        if chain.is_empty() {
            return Err(bad(TlsFile::Cert, "no CERTIFICATE in it".into()));
        }
        let key = PrivateKeyDer::from_pem_slice(&self.key)
            .map_err(|e| bad(TlsFile::Key, format!("no PKCS#8, RSA or EC private key in it ({e})")))?;
        let provider = rustls::crypto::ring::default_provider();
        let certified = CertifiedKey::from_der(chain, key, &provider).map_err(|e| match e {
            rustls::Error::InconsistentKeys(_) => {
                bad(TlsFile::Key, format!("this key is not the key of {}", files.cert_file.display()))
            }
            rustls::Error::InvalidCertificate(_) | rustls::Error::NoCertificatesPresented => {
                bad(TlsFile::Cert, format!("the first certificate does not parse: {e}"))
            }
            e => bad(TlsFile::Key, format!("the key cannot sign: {e}")),
        })?;
        Ok(Arc::new(certified))
    }
}

/// Which of the two files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TlsFile {
    /// `cert_file`.
    Cert,
    /// `key_file`.
    Key,
}

impl TlsFile {
    /// The key naming it in the configuration.
    pub fn key(self) -> &'static str {
        match self {
            TlsFile::Cert => "server.tls.cert_file",
            TlsFile::Key => "server.tls.key_file",
        }
    }
}

/// Why the certificate files cannot be served.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TlsError {
    /// A file cannot be read.
    #[error("cannot read {}: {message}", path.display())]
    Read {
        /// Which file.
        file: TlsFile,
        /// Its path.
        path: PathBuf,
        /// The system's reason.
        message: String,
    },
    /// A file that reads but is not what it should be.
    #[error("{}: {message}", path.display())]
    Bad {
        /// Which file.
        file: TlsFile,
        /// Its path.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl TlsError {
    /// The file the error is about.
    pub fn file(&self) -> TlsFile {
        match self {
            TlsError::Read { file, .. } | TlsError::Bad { file, .. } => *file,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair() -> (String, String) {
        let cert = rcgen::generate_simple_self_signed(vec!["localhost".into()]).unwrap();
        (cert.cert.pem(), cert.signing_key.serialize_pem())
    }

    fn files(dir: &Path, cert: &str, key: &str) -> TlsConfig {
        std::fs::write(dir.join("cert.pem"), cert).unwrap();
        std::fs::write(dir.join("key.pem"), key).unwrap();
        TlsConfig::new(dir.join("cert.pem"), dir.join("key.pem"))
    }

    #[test]
    fn a_matching_pair_loads_and_every_mistake_names_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let (cert, key) = pair();
        let (_, other_key) = pair();
        files(dir.path(), &cert, &key).load().unwrap();

        let err = files(dir.path(), &cert, &other_key).load().unwrap_err();
        assert_eq!(err.file(), TlsFile::Key, "{err}");
        assert!(err.to_string().contains("is not the key of"), "{err}");

        let err = files(dir.path(), &key, &key).load().unwrap_err();
        assert_eq!(err.file(), TlsFile::Cert, "{err}");
        assert!(err.to_string().contains("no CERTIFICATE"), "{err}");

        let err = files(dir.path(), &cert, &cert).load().unwrap_err();
        assert_eq!(err.file(), TlsFile::Key, "{err}");

        let mangled = cert.replace("MII", "M!I");
        let err = files(dir.path(), &mangled, &key).load().unwrap_err();
        assert_eq!(err.file(), TlsFile::Cert, "{err}");

        let missing = TlsConfig::new(dir.path().join("nope.pem"), dir.path().join("key.pem"));
        let err = missing.load().unwrap_err();
        assert!(matches!(err, TlsError::Read { file: TlsFile::Cert, .. }), "{err}");
        assert!(err.to_string().contains("nope.pem"), "{err}");
    }
}
