//! Upgrading a cluster one node at a time, and rolling back (issue 53, item 5): a node of
//! the previous schema follows a node of this one, takes over from it, and hands back.
//!
//! "A node of the previous schema" is this code knowing one migration less
//! (`database.known_schema`, `store::schema::Known::up_to`): an old binary cannot be built
//! here. It starts on a database this schema's node migrated (its code is this release's
//! and uses the newest columns), which is the case that matters: the old node under a
//! newer schema, as the backup after the upgrade of the other node, or as the node rolled
//! back to. With sqlx's migrator it refused to start there (`VersionMissing`).

use std::time::Duration;

use rackd::cli::demo::{Pace, start_with};
use rackd::config::{ClusterConfig, Config};
use rackd::store::{Database, Engine, schema::Known};
use serde_json::{Value, json};

use crate::support::{TestApp, eventually, spawn_on};

const PACE: Pace = Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(20) };

/// A node named `name` on the site's devices, knowing the migrations up to `schema`.
async fn node(db: &str, name: &str, site: &Config, schema: Option<i64>) -> TestApp {
    let (name, devices) = (name.to_owned(), site.devices.clone());
    spawn_on(Database::Postgres(db.to_owned()), move |c| {
        c.devices = devices;
        c.database.known_schema = schema;
        c.cluster =
            Some(ClusterConfig { node: name, lease_ms: 3000, margin_ms: None, url: None, ca_file: None });
    })
    .await
}

/// Waits until `check` holds for `app`'s answer to `GET path` (bounded).
async fn until(app: &TestApp, path: &str, check: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("GET {path} to come right"), Duration::from_secs(30), async || {
        let (status, body) = app.get(path).await;
        if status == 200 && check(&body) { Ok(body) } else { Err(format!("{status} {body}")) }
    })
    .await
}

/// A job submitted to `via`, completed by whichever node drives.
async fn job_runs(via: &TestApp, reference: &str, bay: u16) {
    let job = json!({"kind": "travel", "reference": reference,
                     "to": {"aisle": 2, "row": 1, "bay": bay, "level": 1, "position": 1}});
    let (status, job) = via.post("/api/v1/jobs", &job).await;
    assert_eq!(status, 201, "{job}");
    until(via, &format!("/api/v1/jobs/{}", job["id"]), |j| j["state"] == "completed").await;
}

/// The node `name` as `view` lists it: (version, schema).
fn told(view: &Value, name: &str) -> (Value, Value) {
    let nodes = view["nodes"].as_array().unwrap();
    let node = nodes.iter().find(|n| n["name"] == name).unwrap_or_else(|| panic!("{name} in {view}"));
    (node["version"].clone(), node["schema"].clone())
}

fn is_active(view: &Value) -> bool {
    view["role"] == "active"
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_of_the_previous_schema_follows_takes_over_and_hands_back() {
    let this = Known::new(Engine::Postgres.migrator()).latest();
    let versions: Vec<i64> = Engine::Postgres.migrator().iter().map(|m| m.version).collect();
    let previous = versions[versions.len() - 2];
    let version = json!(env!("CARGO_PKG_VERSION"));
    let db = crate::support::postgres::database().await;
    let mut site = Config::demo();
    let sims = start_with(&mut site, PACE).await.unwrap();

    // "new", of this schema, migrates and drives; "old" follows on the newer schema.
    let new = node(&db, "new", &site, None).await;
    until(&new, "/api/v1/cluster", is_active).await;
    let old = node(&db, "old", &site, Some(previous)).await;
    let view = until(&old, "/api/v1/cluster", |c| c["nodes"].as_array().is_some_and(|n| n.len() == 2)).await;
    assert_eq!(view["role"], "standby", "{view}");
    assert_eq!(
        (view["schema"].clone(), view["database_schema"].clone()),
        (json!(previous), json!(this)),
        "{view}"
    );
    assert_eq!(told(&view, "old"), (version.clone(), json!(previous)));
    assert_eq!(told(&view, "new"), (version.clone(), json!(this)));
    assert_eq!(old.get("/readyz").await, (200, json!({"status": "ok", "role": "standby"})));
    job_runs(&old, "through-old", 3).await;

    // Rolled back: "new" stops, "old" takes over on the newer schema and drives.
    new.stop().await;
    let view = until(&old, "/api/v1/cluster", is_active).await;
    assert_eq!(view["takeovers"], 1, "{view}");
    job_runs(&old, "driven-by-old", 4).await;

    // Upgraded again: "new" follows "old", then takes over from it.
    let new = node(&db, "new", &site, None).await;
    let view = until(&new, "/api/v1/cluster", |c| c["lease"]["holder"] == "old").await;
    assert_eq!(
        (view["role"].clone(), view["database_schema"].clone()),
        (json!("standby"), json!(this)),
        "{view}"
    );
    job_runs(&new, "through-new", 5).await;
    old.stop().await;
    until(&new, "/api/v1/cluster", is_active).await;
    job_runs(&new, "driven-by-new", 6).await;
    assert_eq!(sims.1.violations(), 0, "{:?}", sims.1.violation_log());

    // Neither node changed what the other applied: each migration is in the database
    // once.
    let Database::Postgres(url) = &new.db else { unreachable!() };
    let pool = sqlx::PgPool::connect(url).await.unwrap();
    let applied: Vec<i64> = sqlx::query_scalar("SELECT version FROM _sqlx_migrations ORDER BY version")
        .fetch_all(&pool)
        .await
        .unwrap();
    assert_eq!(applied, versions);
    pool.close().await;
    new.stop().await;
}
