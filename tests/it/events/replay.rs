//! `?since=SEQ`: replay from the log, then live, without gap or duplicate.

use std::time::Duration;

use rackd::store::Engine;
use rstest::rstest;

use super::{assert_consecutive, assert_nothing_more, submit};
use crate::support::ws::Ws;
use crate::support::{spawn_app, spawn_on};

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_reconnect_with_since_misses_nothing_and_repeats_nothing(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let mut ws = Ws::connect(&app.base, "").await;
    assert_eq!(ws.json().await["seq"], 0);
    submit(&app, 10).await;
    let first = ws.events(4).await;
    assert_consecutive(&first, 1);
    ws.close().await;

    // While away: more events.
    submit(&app, 7).await;
    let mut ws = Ws::connect(&app.base, "?since=4").await;
    // Events keep coming while the replay runs.
    let more = tokio::spawn({
        let base = app.base.clone();
        async move {
            let client = reqwest::Client::new();
            for i in 0..20 {
                let body = serde_json::json!({"kind": "light", "location": crate::support::loc(1, 1, 1, 1),
                    "color": "red", "on": i % 2 == 0});
                let r = client.post(format!("{base}/api/v1/jobs")).json(&body).send().await.unwrap();
                assert_eq!(r.status(), 201);
            }
        }
    });
    let events = ws.events(13 + 20).await;
    more.await.unwrap();
    assert_consecutive(&events, 5);
    assert_nothing_more(&app, &mut ws, 4 + 13 + 20).await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn since_with_a_topic_replays_only_that_topic_and_survives_a_restart(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    submit(&app, 3).await;
    let (db, dir) = app.stop().await;
    let app = spawn_on(db, |_| {}).await;
    submit(&app, 2).await;
    let mut ws = Ws::connect(&app.base, "?since=1&topics=jobs").await;
    let events = ws.events(4).await;
    assert_consecutive(&events, 2);
    assert_nothing_more(&app, &mut ws, 5).await;
    drop(dir);
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_since_the_log_cannot_serve_starts_with_a_snapshot(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    submit(&app, 3).await;
    let mut ws = Ws::connect(&app.base, "?since=99").await;
    let snapshot = ws.json().await;
    assert_eq!(snapshot["type"], "snapshot");
    assert_eq!(snapshot["reason"], "since_unknown");
    assert_eq!(snapshot["seq"], 3);
    submit(&app, 1).await;
    assert_consecutive(&ws.events(1).await, 4);
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn retention_keeps_the_newest_event_so_numbers_are_never_reused(#[case] engine: Engine) {
    use rackd::store::writer::{Hooks, Record, Writer};
    let app = spawn_app(engine).await;
    submit(&app, 5).await;
    let (db, dir) = app.stop().await;
    // Prune everything up to now, as the retention task does with old events.
    let pool = rackd::store::open(&db, Duration::from_secs(5)).await.unwrap();
    let (writer, task) = Writer::start(&pool, 16, 16, Hooks::default()).await.unwrap();
    let now = rackd::domain::time::now_ms() + 1;
    writer.record(Record::Prune { before_ms: now, through: i64::MAX, hard_ms: now }).await.unwrap();
    drop(writer);
    task.await.unwrap();
    pool.close().await;

    let app = spawn_on(db, |_| {}).await;
    let mut ws = Ws::connect(&app.base, "?since=2").await;
    let snapshot = ws.json().await;
    assert_eq!(snapshot["reason"], "since_expired", "{snapshot}");
    assert_eq!(snapshot["seq"], 5, "the newest event is kept");
    submit(&app, 1).await;
    assert_consecutive(&ws.events(1).await, 6);
    let mut replay = Ws::connect(&app.base, "?since=4").await;
    assert_consecutive(&replay.events(2).await, 5);
    drop(dir);
}

/// A replay stops at the newest event published. On SQLite a commit is published only once
/// it is on disk: a row beyond that (here one written into the log by hand, as a commit
/// whose sync has not returned would stand) is not replayed; it comes live once published,
/// or never if a power cut took it.
#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_replay_stops_at_the_newest_event_published(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    submit(&app, 3).await;
    let mut db = Raw::connect(&app.db).await;
    db.run("INSERT INTO events (seq, at, type, data) VALUES (4, 0, 'job.updated', '{\"id\":999}')").await;
    let mut ws = Ws::connect(&app.base, "?since=1").await;
    let events = ws.events(2).await;
    assert_consecutive(&events, 2);
    // The row goes, so that the writer's next event takes its number: the sentinel's event
    // must come next, not the row the replay read past.
    db.run("DELETE FROM events WHERE seq = 4").await;
    assert_nothing_more(&app, &mut ws, 3).await;
}

/// A connection of the test's own to the app's database, on either engine.
enum Raw {
    Sqlite(sqlx::SqliteConnection),
    Postgres(sqlx::PgConnection),
}

impl Raw {
    async fn connect(db: &rackd::store::Database) -> Raw {
        use sqlx::{ConnectOptions, Connection};
        match db {
            rackd::store::Database::Sqlite(path) => {
                let options = sqlx::sqlite::SqliteConnectOptions::new()
                    .filename(path)
                    .busy_timeout(Duration::from_secs(5));
                Raw::Sqlite(options.connect().await.unwrap())
            }
            rackd::store::Database::Postgres(url) => {
                Raw::Postgres(sqlx::PgConnection::connect(url).await.unwrap())
            }
        }
    }

    async fn run(&mut self, sql: &'static str) {
        match self {
            Raw::Sqlite(c) => drop(sqlx::raw_sql(sql).execute(c).await.unwrap()),
            Raw::Postgres(c) => drop(sqlx::raw_sql(sql).execute(c).await.unwrap()),
        }
    }
}
