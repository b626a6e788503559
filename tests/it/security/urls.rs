//! Issue 51, "secrets stay secret everywhere": a URL is printed with its password and its
//! secret query parameters (`?token=`, `?code=`, `?sig=`, ...) as `***` in every place one
//! is printed (`src/redact.rs`): `check-config`'s errors (a malformed `database.url`, a
//! webhook's `url`), `check-config --explain`, `GET /api/v1/webhooks` to a viewer, the
//! `db` commands' errors, `rackd healthcheck`, and the log. The real binary and server.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

use rackd::auth::{KeyHash, Role};
use rackd::config::{KeyConfig, WebhookConfig};
use rackd::store::Engine;

use crate::support::{eventually_blocking, spawn_with};

const SECRET: &str = "S3cret-T0ken";
const WHSEC: &str = "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw";

fn rackd(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rackd")).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

fn check_config(text: &str, explain: bool) -> (bool, String, String) {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    std::fs::write(&file, text).unwrap();
    let mut args = vec!["check-config", file.to_str().unwrap()];
    if explain {
        args.push("--explain");
    }
    rackd(&args)
}

fn webhook(url: &str) -> String {
    format!("[[webhooks]]\nname = \"wms\"\nurl = \"{url}\"\nevents = [\"*\"]\nsecret = \"{WHSEC}\"\n")
}

#[test]
fn a_malformed_database_url_is_refused_without_its_password() {
    for url in [
        format!("postgres//rackd:{SECRET}@db.plant/rackd"),
        format!("postgres:rackd:{SECRET}@db.plant/rackd"),
        format!("postgres://rackd:{SECRET}/rackd"),
    ] {
        let (ok, out, err) = check_config(&format!("[database]\nurl = \"{url}\"\n"), false);
        assert!(!ok && err.contains("database.url"), "{url}: {out}{err}");
        assert!(!err.contains(SECRET) && !out.contains(SECRET), "{err}");
    }
}

#[test]
fn a_webhooks_secret_query_parameters_are_hidden_by_explain_and_by_errors() {
    let url = format!("https://wms.plant/events?site=north&token={SECRET}&sig={SECRET}");
    let (ok, out, err) = check_config(&webhook(&url), true);
    assert!(ok, "{err}");
    let line = out.lines().find(|l| l.starts_with("url = ")).unwrap_or_else(|| panic!("{out}"));
    assert!(line.contains("https://wms.plant/events?site=north&token=***&sig=***"), "{line}");
    assert!(!out.contains(SECRET) && !err.contains(SECRET), "{out}{err}");

    // Refused (not http), and named without the token.
    let (ok, out, err) = check_config(&webhook(&format!("ftp://wms.plant/events?code={SECRET}")), false);
    assert!(!ok && err.contains("webhooks[0].url"), "{out}{err}");
    assert!(err.contains("code=***") && !err.contains(SECRET), "{err}");
}

#[tokio::test]
async fn a_viewer_sees_a_webhooks_url_without_its_secrets() {
    // Nothing listens on port 1: deliveries fail, and their errors are shown too.
    let url = format!("http://wms:{SECRET}@127.0.0.1:1/events?access_token={SECRET}&site=north");
    let mut config = WebhookConfig::new("wms", &url, &["*"], WHSEC);
    (config.backoff_ms, config.max_backoff_ms, config.timeout_ms) = (20, 100, 500);
    let app = spawn_with(Engine::Sqlite, |c| {
        c.auth.keys =
            vec![KeyConfig { name: "screen".into(), role: Role::Viewer, hash: KeyHash::of("key-viewer") }];
        c.webhooks = vec![config];
    })
    .await;
    let list = app.client.get(app.url("/api/v1/webhooks")).bearer_auth("key-viewer").send().await.unwrap();
    assert_eq!(list.status(), 200);
    let text = list.text().await.unwrap();
    assert!(!text.contains(SECRET), "{text}");
    let list: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(list["webhooks"][0]["url"], "http://wms:***@127.0.0.1:1/events?access_token=***&site=north");
    app.stop().await;
}

#[test]
fn the_db_commands_and_healthcheck_print_a_url_without_its_secrets() {
    for args in [
        vec!["db", "rollups", "--rebuild", "--database"],
        vec!["db", "archive", "--before", "2026-01-01", "--to", "/nonexistent", "--database"],
        vec!["db", "copy", "--to", "sqlite:/nonexistent/x.db", "--from"],
    ] {
        let url = format!("mysql://rackd:{SECRET}@db.plant/rackd");
        let (ok, out, err) = rackd(&[args.as_slice(), &[url.as_str()]].concat());
        assert!(!ok, "{args:?}: {out}");
        assert!(err.contains("mysql://rackd:***@db.plant/rackd"), "{args:?}: {err}");
        assert!(!err.contains(SECRET), "{args:?}: {err}");
    }
    // Nothing listens on port 1.
    let url = format!("http://probe:{SECRET}@127.0.0.1:1/healthz?token={SECRET}");
    let (ok, out, err) = rackd(&["healthcheck", "--url", &url]);
    assert!(!ok, "{out}");
    assert!(err.contains("http://probe:***@127.0.0.1:1/healthz?token=***"), "{err}");
    assert!(!err.contains(SECRET) && !out.contains(SECRET), "{out}{err}");
}

/// A child process killed when the test ends, however it ends.
struct Killed(std::process::Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn the_log_shows_a_webhooks_url_without_its_secrets() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    // Plain http to another machine: warned about at the start, the URL in the line.
    let url = format!("http://10.255.0.1:9000/events?token={SECRET}");
    let text = format!(
        "[server]\nlisten = \"127.0.0.1:0\"\n[database]\npath = \"{}\"\n{}",
        dir.path().join("rackd.db").display(),
        webhook(&url)
    );
    std::fs::write(&file, text).unwrap();
    let mut server = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["serve", "--config", file.to_str().unwrap()])
        .env("RACKD_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = server.stderr.take().unwrap();
    let lines = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let into = lines.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            into.lock().unwrap().push(line);
        }
    });
    let server = Killed(server);
    eventually_blocking("rackd listening", Duration::from_secs(20), || {
        lines.lock().unwrap().iter().any(|l| l.contains("rackd listening"))
    });
    drop(server);
    let lines = lines.lock().unwrap();
    let all = lines.join("\n");
    assert!(!all.contains(SECRET), "{all}");
    let warning = lines.iter().find(|l| l.contains("WARN") && l.contains("webhooks[0].url"));
    let warning = warning.unwrap_or_else(|| panic!("no warning of the plain http webhook: {all}"));
    assert!(warning.contains("http://10.255.0.1:9000/events?token=***"), "{warning}");
}
