//! How SQLite is set up: its page size (a new database gets rackd's, an existing one keeps
//! its own) and the options it is built with.

use std::time::Duration;

use rackd::store::{self, Database, Pool, SQLITE_PAGE_SIZE, jobs};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode};

use super::light;

async fn page_size(pool: &Pool) -> i64 {
    let Pool::Sqlite(p) = pool else { unreachable!("a SQLite store") };
    sqlx::query_scalar("PRAGMA page_size").fetch_one(p).await.unwrap()
}

#[tokio::test]
async fn a_new_database_gets_rackds_page_size() {
    let (pool, _db, _dir) = super::open(store::Engine::Sqlite).await;
    assert_eq!(page_size(&pool).await, i64::from(SQLITE_PAGE_SIZE));
    assert_ne!(SQLITE_PAGE_SIZE, 4096, "this test must tell rackd's size from SQLite's default");
}

/// A database made with SQLite's default pages (any site's before this setting) opens,
/// migrates and takes jobs as before, with its pages unchanged.
#[tokio::test]
async fn an_existing_database_keeps_its_page_size_and_works() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.db");
    let old = SqliteConnectOptions::new()
        .filename(&path)
        .create_if_missing(true)
        .page_size(4096)
        .journal_mode(SqliteJournalMode::Wal);
    let made = sqlx::SqlitePool::connect_with(old).await.unwrap();
    sqlx::query("CREATE TABLE made_before (id INTEGER PRIMARY KEY)").execute(&made).await.unwrap();
    made.close().await;

    let pool = store::open(&Database::Sqlite(path), Duration::from_secs(5)).await.expect("the store opens");
    assert_eq!(page_size(&pool).await, 4096);
    let (writer, _task) = store::writer::Writer::start(&pool, 64, 64, Default::default()).await.unwrap();
    let created = writer.submit(vec![light("after", 1)]).await.unwrap();
    assert_eq!(created.len(), 1);
    let stored = jobs::list(&pool, &jobs::JobFilter { limit: 10, ..Default::default() }).await.unwrap();
    assert_eq!(stored.iter().map(|j| j.reference.clone().unwrap()).collect::<Vec<_>>(), ["after"]);
}

/// SQLite is built as `.cargo/config.toml` says: without memory statistics, whose mutex every
/// allocation took (a build that missed the setting, a Dockerfile without `.cargo`, fails).
#[tokio::test]
async fn sqlite_is_built_without_memory_statistics() {
    let (pool, _db, _dir) = super::open(store::Engine::Sqlite).await;
    let Pool::Sqlite(p) = &pool else { unreachable!("a SQLite store") };
    let options: Vec<String> = sqlx::query_scalar("PRAGMA compile_options").fetch_all(p).await.unwrap();
    assert!(options.iter().any(|o| o == "DEFAULT_MEMSTATUS=0"), "compile options: {options:?}");
}
