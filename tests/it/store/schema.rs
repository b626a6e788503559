//! A node on a SQLite store whose schema is newer than it knows (`store::schema`): it runs
//! when the newer migration says it is compatible, without touching it, and refuses with a
//! message that names the migration when it is not. "A newer node" is this rackd knowing
//! one migration more (`Known::with`), which the test writes.

use std::borrow::Cow;
use std::time::Duration;

use rackd::store::schema::{Known, SchemaError};
use rackd::store::{self, Database, Engine, OpenError, Pool};
use sqlx::migrate::{Migration, MigrationType};

/// A node of the next release: this one's migrations and one more, `sql`.
fn newer(sql: &'static str) -> (Known, i64) {
    let known = Known::new(Engine::Sqlite.migrator());
    let version = known.latest() + 1;
    let extra = Migration::new(
        version,
        Cow::Borrowed("notes on jobs"),
        MigrationType::Simple,
        sqlx::SqlSafeStr::into_sql_str(sqlx::AssertSqlSafe(sql)),
        false,
    );
    (known.with(extra), version)
}

/// Opens `db` as a node knowing `known` would.
async fn open(db: &Database, known: &Known) -> Result<(Pool, store::schema::Found), OpenError> {
    store::open_known(db, Duration::from_secs(5), Default::default(), known).await
}

/// What `_sqlx_migrations` holds: (version, checksum), in order.
async fn applied(pool: &Pool) -> Vec<(i64, Vec<u8>)> {
    let Pool::Sqlite(p) = pool else { unreachable!("a SQLite store") };
    sqlx::query_as("SELECT version, checksum FROM _sqlx_migrations ORDER BY version")
        .fetch_all(p)
        .await
        .unwrap()
}

#[tokio::test]
async fn a_node_runs_on_a_newer_compatible_schema_and_leaves_it_as_it_is() {
    let dir = tempfile::tempdir().unwrap();
    let db = Database::Sqlite(dir.path().join("rackd.db"));
    let this = Known::new(Engine::Sqlite.migrator()).latest();
    let (next, version) = newer("-- compatible-from: 15\nALTER TABLE jobs ADD COLUMN note TEXT;");
    assert_eq!(this, 15, "the line above names this release's schema");
    let (pool, found) = open(&db, &next).await.expect("the newer node migrates");
    assert_eq!(found.applied.last(), Some(&version));
    let before = applied(&pool).await;
    pool.close().await;

    // This release's node: it runs, says what it found, and applies nothing.
    let (pool, found) =
        open(&db, &Known::new(Engine::Sqlite.migrator())).await.expect("a compatible schema opens");
    assert_eq!((found.known, found.database, found.newer.clone()), (this, version, vec![version]));
    assert!(found.applied.is_empty(), "{found:?}");
    assert_eq!(applied(&pool).await, before, "the newer migration is left as it is");
    store::ready(&pool).await.expect("ready on the newer schema");
    pool.close().await;
    // A whole node serves on it: a job goes in and reads back with the newer column there.
    let app = crate::support::spawn_on(db.clone(), |_| {}).await;
    let (status, job) = app.post("/api/v1/jobs", &crate::support::store("on-a-newer-schema")).await;
    assert_eq!(status, 201, "{job}");
    let (status, read) = app.get(&format!("/api/v1/jobs/{}", job["id"])).await;
    assert_eq!((status, read["reference"].clone()), (200, job["reference"].clone()), "{read}");
    app.stop().await;

    // And the newer node opens it again as it left it.
    let (pool, found) = open(&db, &next).await.expect("the newer node again");
    assert!(found.applied.is_empty() && found.newer.is_empty(), "{found:?}");
    pool.close().await;
}

#[tokio::test]
async fn a_node_refuses_a_newer_schema_marked_incompatible() {
    let dir = tempfile::tempdir().unwrap();
    let db = Database::Sqlite(dir.path().join("rackd.db"));
    // A newer migration that says only nodes knowing it may run on it.
    let (next, version) = newer("-- compatible-from: 16\nALTER TABLE jobs RENAME COLUMN barcode TO box;");
    assert_eq!(version, 16);
    open(&db, &next).await.expect("the newer node migrates").0.close().await;

    let Err(e) = open(&db, &Known::new(Engine::Sqlite.migrator())).await else {
        panic!("an incompatible schema opened")
    };
    assert!(matches!(e, OpenError::Schema(SchemaError::Incompatible { version: 16, .. })), "{e:?}");
    assert_eq!(
        e.to_string(),
        "migrating the schema: the database holds migration 16 (notes on jobs), newer than this rackd knows \
         (schema 15), and it says nodes run on it from schema 16 on: upgrade this node to a release that knows \
         migration 16"
    );
}

#[tokio::test]
async fn a_known_migration_with_other_content_is_still_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let db = Database::Sqlite(dir.path().join("rackd.db"));
    let (pool, _) = open(&db, &Known::new(Engine::Sqlite.migrator())).await.unwrap();
    let Pool::Sqlite(p) = &pool else { unreachable!() };
    sqlx::query("UPDATE _sqlx_migrations SET checksum = X'00' WHERE version = 4").execute(p).await.unwrap();
    pool.close().await;
    let Err(e) = open(&db, &Known::new(Engine::Sqlite.migrator())).await else {
        panic!("a changed migration opened")
    };
    assert!(matches!(e, OpenError::Schema(SchemaError::Modified(4))), "{e:?}");
}
