//! HTTPS and WSS: the handshake's configuration, and the certificate swapped in when its
//! files change, without a restart.
//!
//! Decisions:
//! - One rustls `ServerConfig` for the server's life, whose certificate resolver hands out
//!   the current `Arc<CertifiedKey>`; a reload swaps that `Arc` under a lock taken for a
//!   pointer copy per handshake. Connections already open keep the certificate they were
//!   made with; every new handshake gets the new one.
//! - The files are read again every few seconds (`TlsConfig::reload_every`, 5 s) and their
//!   bytes compared with the last read, rather than watched with inotify (the `notify`
//!   crate): a watch is on an inode, so it misses what rotation tools actually do (write a
//!   new file and rename it over the old one; Kubernetes and Docker secrets swap a
//!   symlink), and it would bring a crate and a thread for two files of a few KiB. The
//!   bytes, not the modification time, decide: a copy that keeps the time (`cp -p`,
//!   `rsync -t`) is still seen.
//! - New files that do not load (a rotation caught between the certificate and its key, a
//!   truncated file) leave the old certificate in service, with one warning per distinct
//!   problem; the next read that loads swaps it in. There is no alarm for it: a certificate
//!   is the site's tooling's to watch, and the log says what happened.
//! - ALPN offers `http/1.1` only, as the plain listener speaks HTTP/1.1 only: a client
//!   that offers h2 too settles on HTTP/1.1.

use std::sync::{Arc, RwLock};

use rustls::server::{ClientHello, ResolvesServerCert};
use rustls::sign::CertifiedKey;
use tokio_rustls::TlsAcceptor;
use tokio_util::sync::CancellationToken;

use crate::config::tls::Pem;
use crate::config::{TlsConfig, TlsError};

/// The certificate being served and the acceptor that serves it.
pub(crate) struct Certificates {
    config: TlsConfig,
    /// The files as last read.
    read: Pem,
    current: Arc<Current>,
    acceptor: TlsAcceptor,
}

/// The resolver: whatever certificate is current.
#[derive(Debug)]
struct Current(RwLock<Arc<CertifiedKey>>);

impl ResolvesServerCert for Current {
    fn resolve(&self, _hello: ClientHello<'_>) -> Option<Arc<CertifiedKey>> {
        Some(self.0.read().unwrap_or_else(|p| p.into_inner()).clone())
    }
}

impl Current {
    fn set(&self, key: Arc<CertifiedKey>) {
        *self.0.write().unwrap_or_else(|p| p.into_inner()) = key;
    }
}

impl Certificates {
    /// Loads the files (an error here stops the start, as `check-config` would have said).
    pub(crate) fn load(config: &TlsConfig) -> Result<Certificates, TlsError> {
        let read = config.read()?;
        let current = Arc::new(Current(RwLock::new(read.certified_key(config)?)));
        let provider = Arc::new(rustls::crypto::ring::default_provider());
        let mut server = rustls::ServerConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .expect("ring's provider supports rustls' default protocol versions")
            .with_no_client_auth()
            .with_cert_resolver(current.clone());
        server.alpn_protocols = vec![b"http/1.1".to_vec()];
        let acceptor = TlsAcceptor::from(Arc::new(server));
        Ok(Certificates { config: config.clone(), read, current, acceptor })
    }

    /// What each connection's handshake runs.
    pub(super) fn acceptor(&self) -> &TlsAcceptor {
        &self.acceptor
    }

    /// Reads the files every `reload_every` until `stop`, and swaps in a certificate whose
    /// files changed and load.
    pub(super) fn watch(&self, stop: CancellationToken) {
        let mut reload = Reload {
            config: self.config.clone(),
            seen: self.read.clone(),
            current: self.current.clone(),
            problem: None,
        };
        tokio::spawn(async move {
            let mut every = tokio::time::interval(reload.config.reload_every);
            every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            every.tick().await;
            loop {
                tokio::select! {
                    _ = stop.cancelled() => return,
                    _ = every.tick() => {}
                }
                let files = reload.config.clone();
                let Ok(read) = tokio::task::spawn_blocking(move || files.read()).await else { return };
                reload.take(read);
            }
        });
    }
}

/// The reload's state between two reads of the files.
struct Reload {
    config: TlsConfig,
    /// The files as last read.
    seen: Pem,
    current: Arc<Current>,
    /// The last problem logged, so that files that stay bad are logged once.
    problem: Option<TlsError>,
}

/// What a read of the files did.
#[derive(Debug, PartialEq)]
enum Reloaded {
    /// The files are as they were.
    Same,
    /// A new certificate is served.
    Swapped,
    /// The files changed but do not load (or cannot be read): the certificate stays.
    Kept,
}

impl Reload {
    fn take(&mut self, read: Result<Pem, TlsError>) -> Reloaded {
        let loaded = read.and_then(|pem| {
            if pem == self.seen {
                return Ok(None);
            }
            self.seen = pem;
            self.seen.certified_key(&self.config).map(Some)
        });
        match loaded {
            Ok(None) => {
                self.problem = None;
                Reloaded::Same
            }
            Ok(Some(key)) => {
                self.current.set(key);
                self.problem = None;
                tracing::info!(cert_file = %self.config.cert_file.display(), "TLS certificate reloaded");
                Reloaded::Swapped
            }
            Err(e) => {
                if self.problem.as_ref() != Some(&e) {
                    tracing::warn!(error = %e, "the TLS certificate files do not load; still serving the previous certificate");
                    self.problem = Some(e);
                }
                Reloaded::Kept
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_pair(
        dir: &std::path::Path,
        key_of: &rcgen::CertifiedKey<rcgen::KeyPair>,
        cert_of: &rcgen::CertifiedKey<rcgen::KeyPair>,
    ) {
        std::fs::write(dir.join("cert.pem"), cert_of.cert.pem()).unwrap();
        std::fs::write(dir.join("key.pem"), key_of.signing_key.serialize_pem()).unwrap();
    }

    fn served(current: &Current) -> Vec<u8> {
        current.0.read().unwrap().cert[0].to_vec()
    }

    #[test]
    fn files_that_do_not_load_leave_the_certificate_in_service_until_good_ones_come() {
        let dir = tempfile::tempdir().unwrap();
        let self_signed = || rcgen::generate_simple_self_signed(vec!["localhost".into()]).unwrap();
        let (first, second) = (self_signed(), self_signed());
        write_pair(dir.path(), &first, &first);
        let config = TlsConfig::new(dir.path().join("cert.pem"), dir.path().join("key.pem"));
        let certificates = Certificates::load(&config).unwrap();
        let mut reload = Reload {
            config: config.clone(),
            seen: certificates.read.clone(),
            current: certificates.current.clone(),
            problem: None,
        };
        assert_eq!(reload.take(config.read()), Reloaded::Same);

        // Half a rotation: the new certificate, the old key.
        std::fs::write(dir.path().join("cert.pem"), second.cert.pem()).unwrap();
        assert_eq!(reload.take(config.read()), Reloaded::Kept);
        assert_eq!(served(&certificates.current), first.cert.der().to_vec());
        assert!(matches!(reload.problem, Some(TlsError::Bad { .. })), "{:?}", reload.problem);
        assert_eq!(reload.take(config.read()), Reloaded::Same, "the same bad files are tried once");
        // A file gone for a moment.
        std::fs::remove_file(dir.path().join("key.pem")).unwrap();
        assert_eq!(reload.take(config.read()), Reloaded::Kept);
        assert_eq!(served(&certificates.current), first.cert.der().to_vec());

        write_pair(dir.path(), &second, &second);
        assert_eq!(reload.take(config.read()), Reloaded::Swapped);
        assert_eq!(served(&certificates.current), second.cert.der().to_vec());
        assert_eq!(reload.problem, None);
    }
}
