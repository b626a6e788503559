//! Group commit, set-based: the number of statements does not grow with the group, and one
//! request the database refuses fails alone while the rest of its group commits.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use futures::future::join_all;
use rackd::store::writer::{Hooks, Outcome, WriteError, Writer};
use rackd::store::{Engine, Pool, events, jobs};
use rstest::rstest;

use super::{light, open};
use crate::support::eventually;

/// Holds the writer in the middle of a group, while `hold` is set. The writer runs on a
/// thread of its own, so requests only make one group for sure when they are all queued
/// while it waits. It parks in the `tell` hook, which the writer calls on its own thread for
/// every job it writes; the `observe` hook would not do: it runs on the sync thread once
/// the group is on disk, while the writer goes on.
#[derive(Default)]
struct Latch {
    hold: AtomicBool,
    parked: AtomicBool,
}

impl Latch {
    /// Called by the writer for each job it writes (its own thread: blocking is fine).
    fn park(&self) {
        if self.hold.load(SeqCst) {
            self.parked.store(true, SeqCst);
            while self.hold.load(SeqCst) {
                std::thread::sleep(Duration::from_millis(1));
            }
            self.parked.store(false, SeqCst);
        }
    }

    /// Runs `first`, and while the writer is held writing it queues every one of
    /// `then` (a submission is queued at its first poll), so that `then` makes one group.
    async fn one_group_after<T: Send + 'static, F: Future + Unpin>(
        &self,
        first: impl Future<Output = T> + Send + 'static,
        mut then: Vec<F>,
    ) -> (T, Vec<F::Output>) {
        self.hold.store(true, SeqCst);
        let first = tokio::spawn(first);
        while !self.parked.load(SeqCst) {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        for f in &mut then {
            assert!(futures::poll!(f).is_pending(), "answered while the writer is held");
        }
        self.hold.store(false, SeqCst);
        (first.await.unwrap(), join_all(then).await)
    }
}

/// A writer that notes (commands, statements) of every group, and its latch.
async fn writer(pool: &Pool) -> (Writer, Arc<Mutex<Vec<(usize, usize)>>>, Arc<Latch>) {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let latch = Arc::new(Latch::default());
    let hooks = Hooks {
        observe: Some({
            let seen = seen.clone();
            Arc::new(move |g| seen.lock().unwrap().push((g.commands, g.statements)))
        }),
        tell: Some({
            let latch = latch.clone();
            Arc::new(move |_| latch.park())
        }),
        ..Hooks::default()
    };
    let (writer, _task) = Writer::start(pool, 4096, 4096, hooks).await.unwrap();
    (writer, seen, latch)
}

/// `n` light jobs, referenced `{prefix}-0` onwards, over 20 bays.
fn lights(prefix: &str, n: usize) -> Vec<rackd::store::jobs::NewJob> {
    (0..n).map(|i| light(&format!("{prefix}-{i}"), (i % 20) as u16 + 1)).collect()
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_group_runs_the_same_statements_for_one_job_or_thousands(#[case] engine: Engine) {
    let (pool, _db, _dir) = open(engine).await;
    let (writer, seen, latch) = writer(&pool).await;
    writer.submit(vec![light("warm-up", 1)]).await.unwrap();
    writer.submit(vec![light("one", 1)]).await.unwrap();
    // Up to 2047 jobs (SQLite's 32766 bound values over 16 columns) go in one statement.
    let batch = lights("batch", 2000);
    let w = writer.clone();
    // 50 requests sent before the writer goes on after the batch: one group.
    let many = (0..50).map(|i| Box::pin(writer.submit(vec![light(&format!("many-{i}"), 2)]))).collect();
    let (batch, many) = latch.one_group_after(async move { w.submit(batch).await }, many).await;
    assert_eq!(batch.unwrap().len(), 2000);
    assert!(many.iter().all(Result::is_ok));
    let seen = seen.lock().unwrap().clone();
    assert_eq!(seen.len(), 4, "{seen:?}");
    let (one, batch, group) = (seen[1], seen[2], seen[3]);
    assert_eq!(group.0, 50, "the 50 requests made one group: {seen:?}");
    assert_eq!(one.1, batch.1, "one job and 2000 jobs: the same statements ({seen:?})");
    assert_eq!(one.1, group.1, "one request and 50: the same statements ({seen:?})");
    let stored = jobs::list(&pool, &jobs::JobFilter { limit: 10_000, ..Default::default() }).await.unwrap();
    assert_eq!(stored.len(), 2052);
    let ids: Vec<i64> = stored.iter().map(|j| j.id).collect();
    assert_eq!(ids, (1..=2052).collect::<Vec<_>>());
}

/// A group with more rows than one statement takes (on SQLite 2047 jobs: 32766 bound values
/// over 16 columns) is written whole and in order, each statement after the one before.
#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_group_beyond_one_statement_is_written_whole_and_in_order(#[case] engine: Engine) {
    let (pool, _db, _dir) = open(engine).await;
    let (writer, seen, _latch) = writer(&pool).await;
    writer.submit(vec![light("warm-up", 1)]).await.unwrap();
    writer.submit(vec![light("one", 1)]).await.unwrap();
    let batch = lights("big", 5000);
    let created = writer.submit(batch).await.unwrap();
    assert_eq!(created.len(), 5000);
    let seen = seen.lock().unwrap().clone();
    // SQLite: three statements of at most 2047 jobs instead of one; history and events take
    // 8191 rows a statement. PostgreSQL: one JSON parameter a table, whatever the size.
    let more = match engine {
        Engine::Sqlite => 2,
        Engine::Postgres => 0,
    };
    assert_eq!(seen[2].1, seen[1].1 + more, "statements of one job, then of 5000: {seen:?}");
    let stored = jobs::list(&pool, &jobs::JobFilter { limit: 10_000, ..Default::default() }).await.unwrap();
    let ids: Vec<i64> = stored.iter().map(|j| j.id).collect();
    assert_eq!(ids, (1..=5002).collect::<Vec<_>>());
    let references: Vec<String> = stored.iter().skip(2).map(|j| j.reference.clone().unwrap()).collect();
    assert_eq!(references, (0..5000).map(|i| format!("big-{i}")).collect::<Vec<_>>());
    for id in [3, 2049, 2050, 4096, 4097, 5002] {
        let history = jobs::history(&pool, id).await.unwrap();
        assert_eq!(history.len(), 1, "job {id}: {history:?}");
    }
    let log = events::after(&pool, 0, 10_000).await.unwrap();
    let seqs: Vec<i64> = log.iter().map(|e| e.seq).collect();
    assert_eq!(seqs, (1..=5002).collect::<Vec<_>>(), "one event per job, numbered without a gap");
    assert!(log[5001].data.contains("big-4999"), "{}", log[5001].data);
}

/// A group is applied as if none of its references were stored; one that was is refused by
/// the unique index, and the group is applied again, reading them: each request is answered
/// as if they had been read at once. The groups after it read them.
#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_stored_reference_in_a_group_is_found_by_its_index(#[case] engine: Engine) {
    let (pool, _db, _dir) = open(engine).await;
    let (writer, seen, latch) = writer(&pool).await;
    writer.submit(vec![light("warm-up", 1)]).await.unwrap();
    writer.submit(vec![light("stored", 2)]).await.unwrap();
    let w = writer.clone();
    let four = vec![
        Box::pin(writer.submit(vec![light("A", 3)])),
        Box::pin(writer.submit(vec![light("stored", 2)])),
        Box::pin(writer.submit(vec![light("B", 4)])),
        Box::pin(writer.submit(vec![light("stored", 5)])),
    ];
    let (first, answers) =
        latch.one_group_after(async move { w.submit(vec![light("first", 1)]).await }, four).await;
    first.unwrap();
    let outcome = |i: usize| match &answers[i] {
        Ok(o) => match &o[0] {
            Outcome::Created { job, .. } => ("created", job.id),
            Outcome::Existing(job) => ("existing", job.id),
        },
        Err(e) => panic!("request {i} refused: {e}"),
    };
    assert_eq!(outcome(0), ("created", 4));
    assert_eq!(outcome(1), ("existing", 2), "the same request again: the stored job");
    assert_eq!(outcome(2), ("created", 5), "no id lost to the attempt rolled back");
    assert!(matches!(&answers[3], Err(WriteError::Conflict(r)) if r == "stored"), "{:?}", answers[3]);
    writer.submit(vec![light("after", 6)]).await.unwrap();
    let seen = seen.lock().unwrap().clone();
    assert_eq!(seen.len(), 5, "{seen:?}");
    assert_eq!(seen[3].0, 4, "the four requests made one group: {seen:?}");
    assert_eq!(
        seen[4].1,
        seen[2].1 + 1,
        "the group after it reads references: one statement more ({seen:?})"
    );
    let stored = jobs::list(&pool, &jobs::JobFilter { limit: 100, ..Default::default() }).await.unwrap();
    let references: Vec<_> = stored.iter().map(|j| j.reference.clone().unwrap()).collect();
    assert_eq!(references, ["warm-up", "stored", "first", "A", "B", "after"]);
    let log = events::after(&pool, 0, 100).await.unwrap();
    let seqs: Vec<i64> = log.iter().map(|e| e.seq).collect();
    assert_eq!(seqs, (1..=6).collect::<Vec<_>>(), "one event per stored job, numbered without a gap");
}

/// Six submissions of 1000 jobs made one group: on SQLite it is written while it is
/// applied (a statement of 2047 jobs goes to SQLite's thread while the next submissions are
/// applied). `late` puts something in the last two submissions that only their own
/// statements find: a job the database refuses (`POISON`), or a reference stored before the
/// group (`stored`, sent again as it was). What went to SQLite before must then be taken
/// back with the rest, and every request answered as if the group had not been streamed.
async fn streamed(engine: Engine, late: &str) {
    let (pool, _db, _dir) = open(engine).await;
    poison(&pool, "ABORT").await;
    let (writer, seen, latch) = writer(&pool).await;
    writer.submit(vec![light("warm-up", 1)]).await.unwrap();
    writer.submit(vec![light("stored", 2)]).await.unwrap();
    let w = writer.clone();
    let six = (0..6)
        .map(|k| {
            let mut jobs = lights(&format!("s{k}"), 1000);
            match (k, late) {
                (4, "POISON") => jobs[500] = light("POISON", 3),
                (5, "stored") => jobs[999] = light("stored", 2),
                _ => {}
            }
            Box::pin(writer.submit(jobs))
        })
        .collect();
    let (first, answers) =
        latch.one_group_after(async move { w.submit(vec![light("first", 1)]).await }, six).await;
    first.unwrap();
    assert_eq!(seen.lock().unwrap()[3].0, 6, "the six submissions made one group");
    let mut expected = Vec::new();
    for (k, answer) in answers.iter().enumerate() {
        if (k, late) == (4, "POISON") {
            assert!(matches!(answer, Err(WriteError::Database(_))), "{answer:?}");
            continue;
        }
        let outcomes = answer.as_ref().unwrap_or_else(|e| panic!("submission {k} refused: {e}"));
        assert_eq!(outcomes.len(), 1000);
        for (i, outcome) in outcomes.iter().enumerate() {
            match outcome {
                Outcome::Created { job, .. } => {
                    assert_eq!(job.id, 4 + expected.len() as i64, "ids in order, without a gap");
                    expected.push(format!("s{k}-{i}"));
                }
                Outcome::Existing(job) => {
                    assert_eq!((k, i, late), (5, 999, "stored"), "{job:?}");
                    assert_eq!(job.id, 2, "the stored job");
                }
            }
        }
    }
    let stored = jobs::list(&pool, &jobs::JobFilter { limit: 10_000, ..Default::default() }).await.unwrap();
    let references: Vec<String> = stored.iter().map(|j| j.reference.clone().unwrap()).collect();
    assert_eq!(references[..3], ["warm-up", "stored", "first"]);
    assert_eq!(references[3..], expected, "each job once, in order, nothing of a refused request");
    let ids: Vec<i64> = stored.iter().map(|j| j.id).collect();
    assert_eq!(ids, (1..=stored.len() as i64).collect::<Vec<_>>());
    for id in [4, 2050, 2051, 4097, stored.len() as i64] {
        assert_eq!(jobs::history(&pool, id).await.unwrap().len(), 1, "job {id}");
    }
    let log = events::after(&pool, 0, 10_000).await.unwrap();
    let seqs: Vec<i64> = log.iter().map(|e| e.seq).collect();
    assert_eq!(seqs, (1..=stored.len() as i64).collect::<Vec<_>>(), "one event per stored job, no gap");
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_large_group_of_submissions_is_written_whole_and_in_order(#[case] engine: Engine) {
    streamed(engine, "").await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_large_group_refused_late_takes_back_what_it_wrote_early(#[case] engine: Engine) {
    streamed(engine, "POISON").await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_large_group_finding_a_stored_reference_late_is_applied_again(#[case] engine: Engine) {
    streamed(engine, "stored").await;
}

/// A trigger that refuses any job with the reference `POISON`. On SQLite, `raise` says how:
/// `ABORT` takes back what the statement wrote, `FAIL` keeps the rows before the refused one
/// (as the writer's `INSERT OR FAIL` does on a constraint).
async fn poison(pool: &Pool, raise: &str) {
    match pool {
        Pool::Sqlite(p) => {
            let sql = format!(
                "CREATE TRIGGER poison BEFORE INSERT ON jobs WHEN NEW.reference = 'POISON' \
                 BEGIN SELECT RAISE({raise}, 'poisoned'); END"
            );
            sqlx::raw_sql(sqlx::AssertSqlSafe(sql)).execute(p).await.unwrap();
        }
        Pool::Postgres(p) => {
            let sql = "CREATE FUNCTION poison() RETURNS trigger AS $$ BEGIN \
                       IF NEW.reference = 'POISON' THEN RAISE EXCEPTION 'poisoned'; END IF; RETURN NEW; END $$ \
                       LANGUAGE plpgsql; \
                       CREATE TRIGGER poison BEFORE INSERT ON jobs FOR EACH ROW EXECUTE FUNCTION poison()";
            sqlx::raw_sql(sql).execute(p).await.unwrap();
        }
    }
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_request_the_database_refuses_fails_alone(#[case] engine: Engine) {
    fails_alone_raised(engine, "ABORT").await;
}

async fn fails_alone_raised(engine: Engine, raise: &str) {
    let (pool, _db, _dir) = open(engine).await;
    poison(&pool, raise).await;
    let (writer, seen, latch) = writer(&pool).await;
    let w = writer.clone();
    let three =
        ["A", "POISON", "B"].into_iter().map(|r| Box::pin(writer.submit(vec![light(r, 3)]))).collect();
    let (first, answers) =
        latch.one_group_after(async move { w.submit(vec![light("first", 1)]).await }, three).await;
    first.unwrap();
    assert_eq!(seen.lock().unwrap()[1].0, 3, "the three requests made one group");
    let created = |a: &Result<Vec<Outcome>, WriteError>| match a {
        Ok(o) => match &o[0] {
            Outcome::Created { job, .. } => job.id,
            Outcome::Existing(_) => panic!("not created: {a:?}"),
        },
        Err(e) => panic!("refused: {e}"),
    };
    assert_eq!(created(&answers[0]), 2);
    assert!(matches!(answers[1], Err(WriteError::Database(_))), "{:?}", answers[1]);
    assert_eq!(created(&answers[2]), 3, "the refused request's id is given back: no gap");
    let next = writer.submit(vec![light("after", 4)]).await.unwrap();
    assert!(matches!(&next[0], Outcome::Created { job, .. } if job.id == 4));
    let stored = jobs::list(&pool, &jobs::JobFilter { limit: 100, ..Default::default() }).await.unwrap();
    let references: Vec<_> = stored.iter().map(|j| j.reference.clone().unwrap()).collect();
    assert_eq!(references, ["first", "A", "B", "after"]);
    let log = events::after(&pool, 0, 100).await.unwrap();
    let seqs: Vec<i64> = log.iter().map(|e| e.seq).collect();
    assert_eq!(seqs, (1..=4).collect::<Vec<_>>(), "one event per stored job, numbered without a gap");
    assert!(log.iter().all(|e| !e.data.contains("POISON")), "no event of the refused request");
}

/// SQLite: a statement refused after it wrote some of its rows (`A` goes in before
/// `POISON` is refused) leaves none of them: the group is rolled back and replayed request
/// by request, `A` and `B` stored once each.
#[tokio::test]
async fn rows_a_refused_statement_wrote_before_its_failure_are_taken_back() {
    fails_alone_raised(Engine::Sqlite, "FAIL").await;
}

/// PostgreSQL only: a server that drops rackd's connections (a restart, a failover, an
/// administrator's `pg_terminate_backend`) costs the group in flight, not the ones after it.
#[tokio::test]
async fn a_broken_connection_costs_one_group_not_the_writer() {
    let (pool, db, _dir) = open(Engine::Postgres).await;
    let (writer, _seen, _latch) = writer(&pool).await;
    writer.submit(vec![light("before", 1)]).await.unwrap();
    let rackd::store::Database::Postgres(url) = db else { unreachable!() };
    let mut admin = <sqlx::PgConnection as sqlx::Connection>::connect(&url).await.unwrap();
    let killed: Vec<bool> = sqlx::query_scalar(
        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity \
         WHERE application_name = 'rackd' AND datname = current_database()",
    )
    .fetch_all(&mut admin)
    .await
    .unwrap();
    assert!(!killed.is_empty(), "rackd's connections were found");
    // Only this test's database: the other tests share the cluster. Termination is a
    // signal: wait until the server has let them go.
    let rackds = "SELECT COUNT(*) FROM pg_stat_activity WHERE application_name = 'rackd' AND datname = current_database()";
    eventually("rackd's connections to go", Duration::from_secs(10), async || {
        let left: i64 = sqlx::query_scalar(rackds).fetch_one(&mut admin).await.unwrap();
        if left == 0 { Ok(()) } else { Err(format!("{left} still there")) }
    })
    .await;
    let during = writer.submit(vec![light("during", 1)]).await;
    assert!(matches!(during, Err(WriteError::Database(_))), "the group in flight fails: {during:?}");
    let after = writer.submit(vec![light("after", 1)]).await.unwrap();
    assert!(matches!(&after[0], Outcome::Created { job, .. } if job.id == 2), "{after:?}");
    let stored = jobs::list(&pool, &jobs::JobFilter { limit: 10, ..Default::default() }).await.unwrap();
    assert_eq!(stored.iter().map(|j| j.reference.clone().unwrap()).collect::<Vec<_>>(), ["before", "after"]);
}
