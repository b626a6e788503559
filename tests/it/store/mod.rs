//! The store's writer on both engines: the same tests against a SQLite file and against a
//! throwaway PostgreSQL cluster (see `tests/it/support/postgres.rs`), through the real writer
//! and the real migrations.

mod archive;
mod copy;
mod cut;
mod full;
mod groups;
mod import;
mod io_error;
mod pages;
mod pg_failover;
pub(crate) mod pg_restart;
mod plans;
mod retention;
mod rollups;
mod schema;

use std::time::Duration;

use rackd::domain::{JobSpec, LightColor, Location, NewJob, Priority};
use rackd::store::{self, Database, Engine, Pool};

/// A fresh, migrated store on `engine`, and the folder to keep while it is used.
pub async fn open(engine: Engine) -> (Pool, Database, Option<tempfile::TempDir>) {
    let (db, dir) = match engine {
        Engine::Sqlite => {
            let dir = tempfile::tempdir().unwrap();
            (Database::Sqlite(dir.path().join("rackd.db")), Some(dir))
        }
        Engine::Postgres => (Database::Postgres(crate::support::postgres::database().await), None),
    };
    let pool = store::open(&db, Duration::from_secs(5)).await.expect("the store opens");
    (pool, db, dir)
}

/// The rows of `sql` on either engine, each as `T` (a tuple of its columns).
pub async fn rows<T>(pool: &Pool, sql: &'static str) -> Vec<T>
where
    T: for<'r> sqlx::FromRow<'r, sqlx::sqlite::SqliteRow>
        + for<'r> sqlx::FromRow<'r, sqlx::postgres::PgRow>
        + Send
        + Unpin,
{
    match pool {
        Pool::Sqlite(p) => sqlx::query_as(sql).fetch_all(p).await.unwrap(),
        Pool::Postgres(p) => sqlx::query_as(sql).fetch_all(p).await.unwrap(),
    }
}

/// The `store` messages a WebSocket subscriber got: when, and whether the store was ok.
pub type Told = std::sync::Arc<std::sync::Mutex<Vec<(tokio::time::Instant, bool)>>>;

/// Follows a subscriber's `store` messages into `told`.
pub fn follow_store(mut ws: crate::support::ws::Ws, told: Told) -> tokio::task::JoinHandle<()> {
    use crate::support::ws::Got;
    tokio::spawn(async move {
        loop {
            match ws.next(Duration::from_secs(60)).await {
                Got::Json(m) if m["type"] == "store" => {
                    told.lock().unwrap().push((tokio::time::Instant::now(), m["ok"] == true));
                }
                Got::Json(_) => {}
                _ => return,
            }
        }
    })
}

/// The value of `rackd_store_commit_failures_total{cause="CAUSE"}` of a running server.
pub async fn failed_commits(app: &crate::support::TestApp, cause: &str) -> u64 {
    let text = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let start = format!("rackd_store_commit_failures_total{{cause=\"{cause}\"}} ");
    let line = text
        .lines()
        .find(|l| l.starts_with(&start))
        .unwrap_or_else(|| panic!("no failed commits for {cause} in {text}"));
    line.rsplit(' ').next().unwrap().parse::<f64>().unwrap() as u64
}

/// A light job with this reference.
pub fn light(reference: &str, bay: u16) -> NewJob {
    NewJob {
        spec: JobSpec::Light {
            location: Location { aisle: 1, row: 1, bay, level: 1, position: 1 },
            color: LightColor::Green,
            on: true,
        },
        reference: Some(reference.to_owned()),
        priority: Priority::default(),
        barcode: None,
        device: None,
        serves: None,
        terms: Default::default(),
    }
}
