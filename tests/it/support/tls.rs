//! Certificates for the TLS tests, made with rcgen: a site's CA ([`Ca`]) and server
//! certificates it signs, written as PEM files; and [`TlsFront`], an https listener in
//! front of a plain HTTP address (what a node behind TLS looks like to another node).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair, KeyUsagePurpose};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;
use tokio_rustls::TlsAcceptor;
use tokio_rustls::rustls::ServerConfig;
use tokio_rustls::rustls::pki_types::pem::PemObject;
use tokio_rustls::rustls::pki_types::{CertificateDer, PrivateKeyDer};

/// A certificate authority of the tests' own.
pub struct Ca {
    /// The CA's certificate, PEM.
    pub pem: String,
    issuer: Issuer<'static, KeyPair>,
}

/// A server's certificate and key, PEM.
pub struct ServerCert {
    pub cert_pem: String,
    pub key_pem: String,
}

impl Ca {
    /// A new CA named `name`.
    pub fn new(name: &str) -> Ca {
        let key = KeyPair::generate().unwrap();
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.distinguished_name.push(DnType::CommonName, name);
        params.key_usages =
            vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign, KeyUsagePurpose::DigitalSignature];
        let pem = params.self_signed(&key).unwrap().pem();
        Ca { pem, issuer: Issuer::new(params, key) }
    }

    /// A server certificate for `localhost` and 127.0.0.1, signed by this CA.
    pub fn server(&self) -> ServerCert {
        self.server_for(&["localhost", "127.0.0.1"])
    }

    /// A server certificate for `names` (DNS names or IP addresses), signed by this CA.
    pub fn server_for(&self, names: &[&str]) -> ServerCert {
        self.signed(names, None)
    }

    /// As [`Ca::server`], valid until `not_after` (rcgen's default is the year 4096).
    pub fn server_until(&self, not_after: time::OffsetDateTime) -> ServerCert {
        self.signed(&["localhost", "127.0.0.1"], Some(not_after))
    }

    fn signed(&self, names: &[&str], not_after: Option<time::OffsetDateTime>) -> ServerCert {
        let key = KeyPair::generate().unwrap();
        let mut params =
            CertificateParams::new(names.iter().map(|n| n.to_string()).collect::<Vec<_>>()).unwrap();
        params.distinguished_name.push(DnType::CommonName, names[0]);
        if let Some(at) = not_after {
            params.not_after = at;
        }
        let cert = params.signed_by(&key, &self.issuer).unwrap();
        ServerCert { cert_pem: cert.pem(), key_pem: key.serialize_pem() }
    }

    /// Writes the CA's certificate to `dir/name` and returns the path.
    pub fn write(&self, dir: &Path, name: &str) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, &self.pem).unwrap();
        path
    }
}

impl ServerCert {
    /// A rustls server configuration with this certificate.
    pub fn server_config(&self) -> Arc<ServerConfig> {
        let chain: Vec<CertificateDer<'static>> =
            CertificateDer::pem_slice_iter(self.cert_pem.as_bytes()).map(Result::unwrap).collect();
        let key = PrivateKeyDer::from_pem_slice(self.key_pem.as_bytes()).unwrap();
        let provider = Arc::new(tokio_rustls::rustls::crypto::ring::default_provider());
        let config = ServerConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .unwrap()
            .with_no_client_auth()
            .with_single_cert(chain, key)
            .unwrap();
        Arc::new(config)
    }
}

/// An https listener on 127.0.0.1 that hands every connection, decrypted, to a plain
/// address (set once it is known: [`TlsFront::forward_to`]); stops when dropped.
pub struct TlsFront {
    pub addr: SocketAddr,
    target: Arc<std::sync::OnceLock<SocketAddr>>,
    task: JoinHandle<()>,
}

impl TlsFront {
    /// A listener with `cert`; connections wait for their target.
    pub async fn bind(cert: &ServerCert) -> TlsFront {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let acceptor = TlsAcceptor::from(cert.server_config());
        let target = Arc::new(std::sync::OnceLock::<SocketAddr>::new());
        let to = target.clone();
        let task = tokio::spawn(async move {
            while let Ok((tcp, _)) = listener.accept().await {
                let (acceptor, to) = (acceptor.clone(), to.clone());
                tokio::spawn(async move {
                    let Ok(mut tls) = acceptor.accept(tcp).await else { return };
                    let Some(to) = to.get().copied() else { return };
                    let Ok(mut plain) = TcpStream::connect(to).await else { return };
                    let _ = tokio::io::copy_bidirectional(&mut tls, &mut plain).await;
                });
            }
        });
        TlsFront { addr, target, task }
    }

    /// Where connections go from now on.
    pub fn forward_to(&self, to: SocketAddr) {
        let _ = self.target.set(to);
    }
}

impl Drop for TlsFront {
    fn drop(&mut self) {
        self.task.abort();
    }
}
