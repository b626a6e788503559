//! Starting and stopping a real rackd for a test: [`TestApp`], on a fresh temporary
//! database of the engine the test names.

use std::time::Duration;

use rackd::app::Application;
use rackd::config::{Config, Sources};
use rackd::service::reload::Reload;
use rackd::store::{Database, Engine};
use serde_json::{Value, json};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

use super::eventually;
use super::held::HeldPort;

/// A running server and a client for it.
pub struct TestApp {
    pub base: String,
    pub client: reqwest::Client,
    pub db: Database,
    /// Let go before the server stops: it holds a handle to the writer, which drains only
    /// once every handle is gone.
    reload: Option<Reload>,
    stop: Option<oneshot::Sender<()>>,
    task: Option<JoinHandle<anyhow::Result<()>>>,
    _dir: Option<tempfile::TempDir>,
}

/// Starts the demo site on a fresh temporary database of `engine`.
pub async fn spawn_app(engine: Engine) -> TestApp {
    spawn_with(engine, |_| {}).await
}

/// A fresh, empty database on `engine`, and the folder to keep while it is used.
pub async fn fresh_database(engine: Engine) -> (Database, Option<tempfile::TempDir>) {
    match engine {
        Engine::Sqlite => {
            let dir = tempfile::tempdir().unwrap();
            (Database::Sqlite(dir.path().join("rackd.db")), Some(dir))
        }
        Engine::Postgres => (Database::Postgres(super::postgres::database().await), None),
    }
}

/// Starts a server with the demo config changed by `edit`, on a fresh temporary database
/// of `engine`.
pub async fn spawn_with(engine: Engine, edit: impl FnOnce(&mut Config)) -> TestApp {
    let (db, dir) = fresh_database(engine).await;
    let mut app = spawn_on(db, edit).await;
    app._dir = dir;
    app
}

/// Puts `db` into `config`.
pub fn use_database(config: &mut Config, db: &Database) {
    match db {
        Database::Sqlite(path) => (config.database.path, config.database.url) = (path.clone(), None),
        Database::Postgres(url) => config.database.url = Some(url.clone()),
    }
}

/// Starts a server on an existing database.
pub async fn spawn_on(db: Database, edit: impl FnOnce(&mut Config)) -> TestApp {
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    use_database(&mut config, &db);
    edit(&mut config);
    start(&config, db, None).await
}

/// As [`spawn_on`], serving on `port`, a port the test holds to start a server there again
/// after this one stops.
pub async fn spawn_on_port(db: Database, port: &HeldPort, edit: impl FnOnce(&mut Config)) -> TestApp {
    let mut config = Config::demo();
    use_database(&mut config, &db);
    edit(&mut config);
    config.server.listen = port.addr();
    let app = Application::build_on(&config, port.listen(), false).await.expect("server starts");
    run(app, &config, db)
}

/// Starts a server from a configuration file made of `text` (its listen address and
/// database set to 127.0.0.1:0 and a fresh SQLite file, and written back), as
/// `serve --config` does: reloads read the file again. Returns the file.
pub async fn spawn_from_file(text: &str) -> (TestApp, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let config = Config::parse(text, &dir.path().join("rackd.toml")).expect("the test's configuration loads");
    let db = Database::Sqlite(dir.path().join("rackd.db"));
    spawn_from_file_on(db, config, dir).await
}

/// As [`spawn_from_file`], with `config` on `db`, the file written in `dir` (kept as long
/// as the server).
pub async fn spawn_from_file_on(
    db: Database,
    mut config: Config,
    dir: tempfile::TempDir,
) -> (TestApp, std::path::PathBuf) {
    let file = dir.path().join("rackd.toml");
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    use_database(&mut config, &db);
    std::fs::write(&file, toml::to_string(&config).unwrap()).unwrap();
    let sources = Sources::file(&file);
    let config = sources.load().expect("the written file loads").config;
    let mut app = start(&config, db, Some(sources)).await;
    app._dir = Some(dir);
    (app, file)
}

/// Starts a server of `config` on `db`, reloading from `sources` if any.
async fn start(config: &Config, db: Database, sources: Option<Sources>) -> TestApp {
    let app = Application::build(config, false).await.expect("server starts");
    if let Some(sources) = sources {
        app.reload_from(sources);
    }
    run(app, config, db)
}

/// Runs `app`, built of `config` on `db`, until stopped.
fn run(app: Application, config: &Config, db: Database) -> TestApp {
    let scheme = if config.server.tls.is_some() { "https" } else { "http" };
    let base = format!("{scheme}://{}", app.local_addr());
    let reload = app.reload();
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(app.run_until(async {
        let _ = stopped.await;
    }));
    let client = reqwest::Client::new();
    TestApp { base, client, db, reload: Some(reload), stop: Some(stop), task: Some(task), _dir: None }
}

impl TestApp {
    /// Keeps `dir` (its database's, say) as long as the server.
    pub fn keep(&mut self, dir: Option<tempfile::TempDir>) {
        self._dir = dir;
    }

    /// Stops the server gracefully and waits until it has finished; keeps the database.
    pub async fn stop(mut self) -> (Database, Option<tempfile::TempDir>) {
        self.reload = None;
        let _ = self.stop.take().unwrap().send(());
        self.task.take().unwrap().await.unwrap().unwrap();
        (self.db.clone(), self._dir.take())
    }

    /// Waits (at most `within`) for the server to stop on its own, with what it ended with.
    pub async fn ended(mut self, within: std::time::Duration) -> anyhow::Result<()> {
        self.reload = None;
        let task = self.task.take().unwrap();
        tokio::time::timeout(within, task).await.expect("the server stops on its own").unwrap()
    }

    /// The running configuration, the devices and the dispatcher, for a test that drives the
    /// service in-process beside the HTTP API. A clone of what it hands out (a dispatcher,
    /// the devices) holds the writer too: let go of it before [`TestApp::stop`].
    pub fn reload(&self) -> &Reload {
        self.reload.as_ref().expect("the server runs")
    }

    /// The flight recorder of a running device.
    pub fn recorder(&self, device: &str) -> Option<std::sync::Arc<rackd::capture::Recorder>> {
        self.reload.as_ref()?.devices().get(device)?.recorder.clone()
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    pub async fn post(&self, path: &str, body: &Value) -> (u16, Value) {
        let r = self.client.post(self.url(path)).json(body).send().await.unwrap();
        split(r).await
    }

    pub async fn get(&self, path: &str) -> (u16, Value) {
        split(self.client.get(self.url(path)).send().await.unwrap()).await
    }

    pub async fn patch(&self, path: &str, body: &Value) -> (u16, Value) {
        split(self.client.patch(self.url(path)).json(body).send().await.unwrap()).await
    }
}

/// Status and JSON body of a response (Null when the body is not JSON).
pub async fn split(r: reqwest::Response) -> (u16, Value) {
    let status = r.status().as_u16();
    let text = r.text().await.unwrap();
    (status, serde_json::from_str(&text).unwrap_or(Value::Null))
}

/// Asserts an error answer: its status and code, with a non-empty message.
pub fn assert_error(got: &(u16, Value), status: u16, code: &str) {
    assert_eq!(got.0, status, "{got:?}");
    assert_eq!(got.1["error"]["code"], code, "{got:?}");
    assert!(got.1["error"]["message"].as_str().is_some_and(|m| !m.is_empty()), "{got:?}");
}

/// A location of the demo site.
pub fn loc(row: u16, bay: u16, level: u16, position: u16) -> Value {
    json!({"aisle": 1, "row": row, "bay": bay, "level": level, "position": position})
}

/// A valid store job.
pub fn store(reference: &str) -> Value {
    json!({"kind": "store", "reference": reference, "barcode": "BOX-1", "to": loc(1, 2, 3, 1)})
}

/// Lists every job, following the cursor.
pub async fn all_jobs(app: &TestApp) -> Vec<Value> {
    let mut jobs = Vec::new();
    let mut cursor = String::new();
    loop {
        let (status, page) = app.get(&format!("/api/v1/jobs?limit=1000{cursor}")).await;
        assert_eq!(status, 200, "{page}");
        jobs.extend(page["jobs"].as_array().unwrap().iter().cloned());
        match page["next_cursor"].as_str() {
            Some(c) => cursor = format!("&cursor={c}"),
            None => return jobs,
        }
    }
}

/// Waits until `n` jobs have ended (bounded: fails after `secs` seconds), returning all jobs.
pub async fn wait_ended(app: &TestApp, n: usize, secs: u64) -> Vec<Value> {
    let what = format!("{n} jobs to end");
    eventually(what, Duration::from_secs(secs), async || {
        let jobs = all_jobs(app).await;
        let ended = jobs
            .iter()
            .filter(|j| ["completed", "failed", "cancelled"].contains(&j["state"].as_str().unwrap()))
            .count();
        if ended >= n { Ok(jobs) } else { Err(format!("{ended} ended")) }
    })
    .await
}

/// Waits (bounded: fails after `secs` seconds) until `count()` has grown by `more` from its
/// value now. With a simulator's request counter this is the positive signal that a device
/// task went round its loop again (each poll asks the machine, and every poll is followed by
/// a dispatch attempt), so a test can then assert that something did NOT happen without
/// sleeping a fixed time and hoping it was long enough.
pub async fn wait_for_more(what: &str, more: u64, secs: u64, count: impl Fn() -> u64) {
    let from = count();
    eventually(format!("{more} more {what}"), Duration::from_secs(secs), async || {
        let grown = count().saturating_sub(from);
        if grown >= more { Ok(()) } else { Err(format!("{grown} more")) }
    })
    .await
}

/// Another connection holding the database's write lock (SQLite: `BEGIN IMMEDIATE`;
/// PostgreSQL: an exclusive lock on `jobs`), so that rackd's writer waits.
pub enum WriteLock {
    Sqlite(sqlx::SqliteConnection),
    Postgres(sqlx::PgConnection),
}

impl WriteLock {
    pub async fn take(db: &Database) -> WriteLock {
        use sqlx::Connection;
        match db {
            Database::Sqlite(path) => {
                let mut c =
                    sqlx::SqliteConnection::connect(&format!("sqlite:{}", path.display())).await.unwrap();
                sqlx::raw_sql("BEGIN IMMEDIATE").execute(&mut c).await.unwrap();
                WriteLock::Sqlite(c)
            }
            Database::Postgres(url) => {
                let mut c = sqlx::PgConnection::connect(url).await.unwrap();
                sqlx::raw_sql("BEGIN; LOCK TABLE jobs IN EXCLUSIVE MODE").execute(&mut c).await.unwrap();
                WriteLock::Postgres(c)
            }
        }
    }

    pub async fn release(self) {
        match self {
            WriteLock::Sqlite(mut c) => drop(sqlx::raw_sql("ROLLBACK").execute(&mut c).await.unwrap()),
            WriteLock::Postgres(mut c) => drop(sqlx::raw_sql("ROLLBACK").execute(&mut c).await.unwrap()),
        }
    }
}
