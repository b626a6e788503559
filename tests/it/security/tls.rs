//! Bearer keys crossed the plant LAN in clear text: rackd spoke plain HTTP only. With
//! `[server.tls]` it serves HTTPS and WSS on its one port, with the site's certificate,
//! picks up a rotated certificate without a restart, and `healthcheck` and `check-config`
//! know about it. The certificates are made here with rcgen: a site CA, and a server
//! certificate it signs. Before the fix, `[server.tls]` was an unknown key.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use futures::StreamExt;
use rackd::config::TlsConfig;
use rackd::store::Engine;
use rcgen::KeyPair;
use tokio_tungstenite::tungstenite::Message;

use crate::support::tls::{Ca, ServerCert};
use crate::support::{TestApp, eventually, spawn_with, store};

/// Writes a certificate and key into `dir` as a site's tooling does: a new file renamed
/// over the old one.
pub(super) fn install(dir: &Path, pair: &ServerCert) -> (PathBuf, PathBuf) {
    let (cert_file, key_file) = (dir.join("server.crt"), dir.join("server.key"));
    for (path, text) in [(&cert_file, &pair.cert_pem), (&key_file, &pair.key_pem)] {
        let new = path.with_extension("new");
        std::fs::write(&new, text).unwrap();
        std::fs::rename(&new, path).unwrap();
    }
    (cert_file, key_file)
}

/// A server with `[server.tls]` on the files in `dir`, read again every 50 ms.
pub(super) async fn spawn_tls(dir: &Path, pair: &ServerCert) -> TestApp {
    let (cert, key) = install(dir, pair);
    let app = spawn_with(Engine::Sqlite, |c| {
        let mut tls = TlsConfig::new(cert, key);
        tls.reload_every = Duration::from_millis(50);
        c.server.tls = Some(tls);
    })
    .await;
    assert!(app.base.starts_with("https://127.0.0.1:"), "{}", app.base);
    app
}

/// An HTTPS client that trusts `ca` alone.
pub(super) fn client(ca: &Ca) -> reqwest::Client {
    reqwest::Client::builder()
        .tls_built_in_root_certs(false)
        .add_root_certificate(reqwest::Certificate::from_pem(ca.pem.as_bytes()).unwrap())
        .build()
        .unwrap()
}

/// The status of `GET /healthz` from a new client trusting `ca`, or why it failed.
async fn healthz(app: &TestApp, ca: &Ca) -> Result<u16, String> {
    match client(ca).get(app.url("/healthz")).send().await {
        Ok(r) => Ok(r.status().as_u16()),
        Err(e) => Err(format!("{:?}", anyhow::Error::from(e))),
    }
}

#[tokio::test]
async fn https_and_wss_clients_connect_with_the_site_ca_and_a_rotated_certificate_needs_no_restart() {
    let dir = tempfile::tempdir().unwrap();
    let site = Ca::new("Site CA");
    let app = spawn_tls(dir.path(), &site.server()).await;
    let https = client(&site);
    let r = https.post(app.url("/api/v1/jobs")).json(&store("tls-1")).send().await.unwrap();
    assert_eq!(r.status(), 201, "a job submitted over HTTPS");
    assert_eq!(healthz(&app, &site).await, Ok(200));

    // One port, TLS only: no plain HTTP beside it, and a client without the site's CA
    // (the public roots alone) refuses the server.
    let plain = app.base.replacen("https://", "http://", 1);
    assert!(reqwest::get(format!("{plain}/healthz")).await.is_err(), "plain HTTP on the TLS port");
    let public = reqwest::Client::new().get(app.url("/healthz")).send().await;
    let refused = format!("{:?}", anyhow::Error::from(public.unwrap_err()));
    assert!(refused.contains("UnknownIssuer"), "{refused}");

    // WSS, trusting the site's CA.
    let mut roots = rustls::RootCertStore::empty();
    roots.add(rustls::pki_types::pem::PemObject::from_pem_slice(site.pem.as_bytes()).unwrap()).unwrap();
    let tls = rustls::ClientConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(roots)
        .with_no_client_auth();
    let url = format!("{}/api/v1/ws?topics=jobs", app.base.replacen("https://", "wss://", 1));
    let connector = tokio_tungstenite::Connector::Rustls(Arc::new(tls));
    let (mut ws, _) =
        tokio_tungstenite::connect_async_tls_with_config(url, None, false, Some(connector)).await.unwrap();
    let mut next_json = async || loop {
        match tokio::time::timeout(Duration::from_secs(10), ws.next()).await.expect("a message within 10 s") {
            Some(Ok(Message::Text(text))) => {
                return serde_json::from_str::<serde_json::Value>(&text).unwrap();
            }
            Some(Ok(_)) => continue,
            other => panic!("the WSS stream ended: {other:?}"),
        }
    };
    assert_eq!(next_json().await["type"], "snapshot");

    // The site's tooling rotates the certificate (to one of another CA, to tell them apart):
    // the next connection gets the new one, without a restart.
    let other = Ca::new("Next CA");
    install(dir.path(), &other.server());
    eventually("a new connection to get the new certificate", Duration::from_secs(10), async || {
        healthz(&app, &other).await
    })
    .await;
    let old = healthz(&app, &site).await;
    assert!(old.as_ref().is_err_and(|e| e.contains("UnknownIssuer")), "{old:?}");
    // A connection made before keeps its certificate and its stream.
    let r = client(&other).post(app.url("/api/v1/jobs")).json(&store("tls-2")).send().await.unwrap();
    assert_eq!(r.status(), 201);
    let event = next_json().await;
    assert_eq!(event["data"]["reference"], "tls-2", "{event}");
}

/// `rackd healthcheck` against a TLS server: `--ca-file` trusts the site's CA, and
/// `--server-name` checks the certificate against its name when the URL is an address.
#[tokio::test]
async fn healthcheck_checks_an_https_server_with_the_site_ca_and_its_name() {
    let dir = tempfile::tempdir().unwrap();
    let site = Ca::new("Site CA");
    let app = spawn_tls(dir.path(), &site.server_for(&["rackd.plant.local"])).await;
    let ca_file = dir.path().join("ca.pem");
    std::fs::write(&ca_file, &site.pem).unwrap();
    let check = async |args: &[&str]| {
        let out = tokio::process::Command::new(env!("CARGO_BIN_EXE_rackd"))
            .args(["healthcheck", "--url", &app.base])
            .args(args)
            .env_remove("RACKD_HEALTHCHECK_CA_FILE")
            .env_remove("RACKD_HEALTHCHECK_SERVER_NAME")
            .output()
            .await
            .unwrap();
        (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let ca = ca_file.to_str().unwrap();
    let (ok, err) = check(&["--ca-file", ca, "--server-name", "rackd.plant.local"]).await;
    assert!(ok, "{err}");
    let (ok, err) = check(&["--server-name", "rackd.plant.local"]).await;
    assert!(!ok && err.contains("UnknownIssuer"), "without the site's CA: {err}");
    let (ok, err) = check(&["--ca-file", ca]).await;
    assert!(!ok && err.contains("not valid for name"), "127.0.0.1 is not the certificate's name: {err}");
}

/// `check-config` loads the files as `serve` would, and names the key at fault.
#[test]
fn check_config_loads_the_certificate_files() {
    let dir = tempfile::tempdir().unwrap();
    let site = Ca::new("Site CA");
    let (cert, key) = install(dir.path(), &site.server_for(&["localhost"]));
    let file = dir.path().join("rackd.toml");
    let check = |cert: &Path, key: &Path| {
        let text = format!("[server.tls]\ncert_file = {cert:?}\nkey_file = {key:?}\n");
        std::fs::write(&file, text).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_rackd"))
            .args(["check-config", file.to_str().unwrap()])
            .output()
            .unwrap();
        (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let (ok, err) = check(&cert, &key);
    assert!(ok, "{err}");
    let other_key = dir.path().join("other.key");
    std::fs::write(&other_key, KeyPair::generate().unwrap().serialize_pem()).unwrap();
    let (ok, err) = check(&cert, &other_key);
    assert!(!ok && err.contains(":3:1: server.tls.key_file: ") && err.contains("is not the key of"), "{err}");
    let (ok, err) = check(&dir.path().join("missing.crt"), &key);
    assert!(!ok && err.contains(":2:1: server.tls.cert_file: cannot read "), "{err}");
}
