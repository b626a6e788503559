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
//!   problem; the next read that loads swaps it in. What is served (its end of validity,
//!   whether the files as they are now are refused) goes to a `watch` ([`Served`]), from
//!   which [`super::certificate`] raises the `certificate` alarms and keeps `/metrics`'
//!   figures: a certificate about to expire, or a renewal that did not load, is seen by
//!   whoever watches the alarms, not only by whoever reads the log.
//! - ALPN offers `http/1.1` only, as the plain listener speaks HTTP/1.1 only: a client
//!   that offers h2 too settles on HTTP/1.1.

use std::sync::{Arc, RwLock};

use rustls::server::{ClientHello, ResolvesServerCert};
use rustls::sign::CertifiedKey;
use time::OffsetDateTime;
use tokio::sync::watch;
use tokio_rustls::TlsAcceptor;
use tokio_util::sync::CancellationToken;

use super::certificate::{Served, not_after};
use crate::config::tls::Pem;
use crate::config::{TlsConfig, TlsError};

/// The certificate being served and the acceptor that serves it.
pub(crate) struct Certificates {
    config: TlsConfig,
    /// The files as last read.
    read: Pem,
    current: Arc<Current>,
    acceptor: TlsAcceptor,
    /// What is served, told as it changes.
    served: watch::Sender<Served>,
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

    /// When the certificate being served expires.
    fn expires(&self) -> Option<OffsetDateTime> {
        not_after(self.0.read().unwrap_or_else(|p| p.into_inner()).cert.first()?)
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
        let served = watch::Sender::new(Served { expires: current.expires(), refused: None });
        Ok(Certificates { config: config.clone(), read, current, acceptor, served })
    }

    /// What is served, as it changes (the alarms and `/metrics`).
    pub(crate) fn served(&self) -> watch::Receiver<Served> {
        self.served.subscribe()
    }

    /// What each connection's handshake runs.
    pub(super) fn acceptor(&self) -> &TlsAcceptor {
        &self.acceptor
    }

    /// Reads the files every `reload_every` until `stop`, and swaps in a certificate whose
    /// files changed and load.
    pub(super) fn watch(&self, stop: CancellationToken) {
        let mut reload = Reload::new(self);
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
    /// Why those do not load (None: they are served).
    seen_problem: Option<TlsError>,
    current: Arc<Current>,
    /// Why the files as they are now are not served, while they are not; logged when it
    /// changes, so that files that stay bad are logged once.
    problem: Option<TlsError>,
    served: watch::Sender<Served>,
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
    fn new(certificates: &Certificates) -> Reload {
        Reload {
            config: certificates.config.clone(),
            seen: certificates.read.clone(),
            seen_problem: None,
            current: certificates.current.clone(),
            problem: None,
            served: certificates.served.clone(),
        }
    }

    fn take(&mut self, read: Result<Pem, TlsError>) -> Reloaded {
        let (reloaded, problem) = match read {
            Err(e) => (Reloaded::Kept, Some(e)),
            // Tried once: the same files that did not load still do not.
            Ok(pem) if pem == self.seen => (Reloaded::Same, self.seen_problem.clone()),
            Ok(pem) => {
                let loaded = pem.certified_key(&self.config);
                self.seen = pem;
                match loaded {
                    Ok(key) => {
                        self.current.set(key);
                        self.seen_problem = None;
                        tracing::info!(cert_file = %self.config.cert_file.display(), "TLS certificate reloaded");
                        (Reloaded::Swapped, None)
                    }
                    Err(e) => {
                        self.seen_problem = Some(e.clone());
                        (Reloaded::Kept, Some(e))
                    }
                }
            }
        };
        if problem != self.problem {
            if let Some(e) = &problem {
                tracing::warn!(error = %e, "the TLS certificate files do not load; still serving the previous certificate");
            }
            self.problem = problem;
        }
        let now =
            Served { expires: self.current.expires(), refused: self.problem.as_ref().map(|e| e.to_string()) };
        self.served.send_if_modified(|told| {
            let changed = *told != now;
            *told = now;
            changed
        });
        reloaded
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
        let told = certificates.served();
        let mut reload = Reload::new(&certificates);
        assert_eq!(reload.take(config.read()), Reloaded::Same);
        assert_eq!(told.borrow().refused, None);

        // Half a rotation: the new certificate, the old key.
        std::fs::write(dir.path().join("cert.pem"), second.cert.pem()).unwrap();
        assert_eq!(reload.take(config.read()), Reloaded::Kept);
        assert_eq!(served(&certificates.current), first.cert.der().to_vec());
        assert!(matches!(reload.problem, Some(TlsError::Bad { .. })), "{:?}", reload.problem);
        assert_eq!(reload.take(config.read()), Reloaded::Same, "the same bad files are tried once");
        let refused = told.borrow().refused.clone().unwrap_or_default();
        assert!(refused.contains("is not the key of"), "told while they stay bad: {refused}");
        // A file gone for a moment.
        std::fs::remove_file(dir.path().join("key.pem")).unwrap();
        assert_eq!(reload.take(config.read()), Reloaded::Kept);
        assert_eq!(served(&certificates.current), first.cert.der().to_vec());

        write_pair(dir.path(), &second, &second);
        assert_eq!(reload.take(config.read()), Reloaded::Swapped);
        assert_eq!(served(&certificates.current), second.cert.der().to_vec());
        assert_eq!(reload.problem, None);
        assert_eq!(certificates.served().borrow().refused, None);

        // Bad files, then the served ones back as they were: nothing refused any more.
        std::fs::write(dir.path().join("key.pem"), first.signing_key.serialize_pem()).unwrap();
        assert_eq!(reload.take(config.read()), Reloaded::Kept);
        write_pair(dir.path(), &second, &second);
        assert_eq!(reload.take(config.read()), Reloaded::Swapped, "loaded again");
        assert_eq!(certificates.served().borrow().refused, None);
    }
}
