//! The database link (finding: "sqlx built without TLS": `?sslmode=require` failed with
//! "built without TLS support" and `prefer` silently connected in plaintext).
//!
//! Against a PostgreSQL that only speaks TLS ([`crate::support::postgres::tls_database`]):
//! `require` connects, `verify-full` with the site's CA (`database.ca_file`, or
//! `sslrootcert` in the URL) connects, `verify-full` against another CA is a startup error
//! that says what is wrong, and a URL that says nothing about TLS still gets it. The
//! configurations are written as a site writes them (TOML), and the service is started
//! for real and asked `/readyz`.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use rackd::app::Application;
use rackd::config::Config;

use crate::support::eventually_blocking;
use crate::support::postgres::tls_database;

/// A site's file with this `[database]` section (no devices), loaded as rackd loads it.
fn config(database: &str) -> Config {
    let text = format!("[server]\nlisten = \"127.0.0.1:0\"\n\n[database]\n{database}\n");
    Config::parse(&text, Path::new("site.toml")).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// Starts rackd on `config`, asks `/readyz`, stops it; or the startup error.
async fn serve(config: &Config) -> Result<(), String> {
    let app = Application::build(config, false).await.map_err(|e| rackd::cli::describe(&e))?;
    let url = format!("http://{}/readyz", app.local_addr());
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(app.run_until(async {
        let _ = stopped.await;
    }));
    let status = reqwest::get(&url).await.unwrap().status();
    let _ = stop.send(());
    task.await.unwrap().unwrap();
    assert_eq!(status, 200, "/readyz");
    Ok(())
}

fn toml_path(path: &Path) -> String {
    toml::Value::String(path.display().to_string()).to_string()
}

#[tokio::test]
async fn sslmode_require_connects_to_a_server_that_refuses_plaintext() {
    let (url, _) = tls_database().await;
    let plain = serve(&config(&format!("url = \"{url}?sslmode=disable\""))).await.unwrap_err();
    assert!(plain.contains("no encryption"), "the server refuses plaintext: {plain}");
    serve(&config(&format!("url = \"{url}?sslmode=require\""))).await.unwrap();
}

#[tokio::test]
async fn verify_full_connects_with_the_sites_ca_from_the_file_or_the_url() {
    let (url, cluster) = tls_database().await;
    let with_ca_file = format!("url = \"{url}?sslmode=verify-full\"\nca_file = {}", toml_path(&cluster.ca));
    serve(&config(&with_ca_file)).await.unwrap();
    let in_url = format!("url = \"{url}?sslmode=verify-full&sslrootcert={}\"", cluster.ca.display());
    serve(&config(&in_url)).await.unwrap();
}

#[tokio::test]
async fn verify_full_against_another_ca_is_a_startup_error_that_says_so() {
    let (url, cluster) = tls_database().await;
    let wrong = format!("url = \"{url}?sslmode=verify-full\"\nca_file = {}", toml_path(&cluster.wrong_ca));
    let err = serve(&config(&wrong)).await.unwrap_err();
    assert!(err.contains("certificate"), "{err}");
    assert!(
        err.contains("database.ca_file") && err.contains(&cluster.wrong_ca.display().to_string()),
        "{err}"
    );
    assert!(err.contains("verify-full"), "{err}");
}

#[tokio::test]
async fn a_url_without_sslmode_still_gets_tls_from_a_server_that_offers_it() {
    // Loopback and no sslmode: libpq's `prefer`, which now means TLS when the server has it
    // (it used to mean plaintext always, which this server refuses).
    let (url, _) = tls_database().await;
    serve(&config(&format!("url = \"{url}\""))).await.unwrap();
}

/// `rackd serve` in the background, killed when dropped.
struct Server(std::process::Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[tokio::test]
async fn the_startup_log_tells_whether_the_link_is_encrypted_and_never_the_password() {
    let (url, _) = tls_database().await;
    let with_password = url.replacen("postgres@", "postgres:S3cret-Pa55@", 1);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    let text = format!(
        "[server]\nlisten = \"127.0.0.1:0\"\n[database]\nurl = \"{with_password}?sslmode=require\"\n"
    );
    std::fs::write(&file, text).unwrap();
    let log = dir.path().join("stderr");
    let child = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["serve", "--config", file.to_str().unwrap()])
        .env("RACKD_LOG", "debug")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let server = Server(child);
    let line = tokio::task::spawn_blocking(move || {
        eventually_blocking("the database link's line in the log", Duration::from_secs(20), || {
            let text = std::fs::read_to_string(&log).ok()?;
            text.lines().find(|l| l.contains("database link")).map(str::to_owned).map(|l| (l, text))
        })
    })
    .await
    .unwrap();
    drop(server);
    let (line, text) = line;
    assert!(line.contains("encrypted") && line.contains("TLS"), "{line}");
    assert!(!text.contains("S3cret-Pa55"), "the password in the log:\n{text}");
}
