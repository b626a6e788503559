//! CA files, read and checked as `check-config` and startup check them: `database.ca_file`
//! (and a URL's `sslrootcert`) for PostgreSQL, `cluster.ca_file` for forwarding to another
//! node over https.
//!
//! A CA file is PEM with one or more `CERTIFICATE` blocks (other blocks are skipped, as
//! rustls and sqlx skip them); each must be an X.509 certificate that rustls accepts as a
//! trust anchor, so that a file that is missing, empty, not PEM, or holds a damaged
//! certificate is refused with its path before anything connects, rather than at the first
//! connection (or never, when the mode would not read it).

use std::path::Path;

use rustls::RootCertStore;
use rustls::pki_types::CertificateDer;
use rustls::pki_types::pem::PemObject;

/// Why a CA file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CaError {
    /// It cannot be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// It holds no PEM certificate.
    #[error("{0} holds no certificate (expected PEM: -----BEGIN CERTIFICATE-----)")]
    Empty(String),
    /// A block that is not a certificate rustls can use.
    #[error("{path}: certificate {n} is not valid: {why}")]
    Invalid {
        /// The file.
        path: String,
        /// Which certificate, from 1.
        n: usize,
        /// What is wrong.
        why: String,
    },
}

/// The certificates of the CA file at `path`, each checked as a trust anchor.
pub fn read_ca(path: &Path) -> Result<Vec<CertificateDer<'static>>, CaError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| CaError::Read { path: name.clone(), source })?;
    let mut store = RootCertStore::empty();
    let mut certs = Vec::new();
    for (i, cert) in CertificateDer::pem_slice_iter(&bytes).enumerate() {
        let invalid = |why: String| CaError::Invalid { path: name.clone(), n: i + 1, why };
        let cert = cert.map_err(|e| invalid(e.to_string()))?;
        store.add(cert.clone()).map_err(|e| invalid(e.to_string()))?;
        certs.push(cert);
    }
    if certs.is_empty() {
        return Err(CaError::Empty(name));
    }
    Ok(certs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_without_a_usable_certificate_is_refused_with_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("ca.pem");
        let missing = read_ca(&file).unwrap_err().to_string();
        assert!(missing.starts_with(&format!("cannot read {}", file.display())), "{missing}");
        std::fs::write(&file, "not a certificate\n").unwrap();
        assert!(matches!(read_ca(&file), Err(CaError::Empty(_))));
        std::fs::write(&file, "-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n").unwrap();
        let err = read_ca(&file).unwrap_err().to_string();
        assert!(err.contains("certificate 1 is not valid"), "{err}");
    }
}
