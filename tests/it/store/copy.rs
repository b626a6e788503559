//! `rackd db copy` (src/store/copy.rs): a store with history copied from SQLite to
//! PostgreSQL and back reads the same through every query the API uses, ids and event
//! numbers included.

use rackd::domain::{AlarmClass, AlarmKind, JobState, Location, LocationLock, Pause, Target, Transition};
use rackd::store::alarms::{AlarmFilter, NewAlarm};
use rackd::store::writer::{Change, Hooks, Outcome, Record, Writer};
use rackd::store::{self, Engine, Pool, alarms, controls, events, jobs, locations, webhooks};
use time::OffsetDateTime;

use super::{light, open};

fn step(transition: Transition) -> Change {
    Change::Transition { transition, cause: "test".into(), expect: None, failure: None, forced: false }
}

/// A store with jobs in every state, history, locations changed and locked, a pause, an
/// alarm raised and cleared and one active, the audit log and the events of all that.
async fn site(pool: &Pool) {
    let layout = rackd::config::Config::demo().layout();
    locations::seed(pool, &layout, 1).await.unwrap();
    let (writer, task) = Writer::start(pool, 64, 64, Hooks::default()).await.unwrap();
    let mut ids = Vec::new();
    for i in 0..12u16 {
        match &writer.submit(vec![light(&format!("J-{i}"), i % 5 + 1)]).await.unwrap()[0] {
            Outcome::Created { job, .. } => ids.push(job.id),
            other => panic!("{other:?}"),
        }
    }
    for &id in &ids[..8] {
        writer.change(id, step(Transition::Dispatch)).await.unwrap();
    }
    for &id in &ids[..4] {
        writer.change(id, step(Transition::Start)).await.unwrap();
        writer.change(id, step(Transition::Complete)).await.unwrap();
    }
    writer.change(ids[9], Change::cancel_queued()).await.unwrap();
    let at = OffsetDateTime::from_unix_timestamp(1_800_000_000).unwrap();
    let by = Pause { by: "ops".into(), reason: Some("inspection".into()), at };
    writer.record(Record::Pause { target: Target::Device("crane1".into()), paused: true, by }).await.unwrap();
    let place = Location { aisle: 1, row: 2, bay: 3, level: 1, position: 1 };
    let lock = LocationLock { by: "ops".into(), reason: "bent beam".into(), job: None, at };
    writer.record(Record::Lock { location: place, lock }).await.unwrap();
    for code in [41, 42] {
        let alarm = NewAlarm {
            device: "crane1".into(),
            kind: AlarmKind::Device,
            code,
            class: AlarmClass::Hardware,
            text: format!("alarm {code}"),
            detail: Some("D205".into()),
            action: Some("go to the crane".into()),
        };
        writer.record(Record::AlarmRaised(alarm)).await.unwrap();
    }
    let cleared = Record::AlarmCleared { device: "crane1".into(), key: (AlarmKind::Device, 41) };
    writer.record(cleared).await.unwrap();
    let ack = Record::Acknowledge { alarm: 2, by: "ops".into(), note: Some("seen".into()) };
    writer.record(ack).await.unwrap();
    let row = webhooks::Row {
        name: "wms".into(),
        cursor: 7,
        last_ok_at: Some(5),
        updated_at: 6,
        ..Default::default()
    };
    let tries = [(6, "failed", Some(500)), (7, "delivered", Some(204))].map(|(seq, outcome, status)| {
        webhooks::Delivery {
            id: 0,
            name: "wms".into(),
            seq,
            attempt: 1,
            status,
            outcome: outcome.into(),
            latency_ms: 3,
            error: None,
            at: 5,
        }
    });
    let progress = webhooks::Progress { row, deliveries: tries.to_vec() };
    writer.record(Record::Webhook { progress, audit: None }).await.unwrap();
    drop(writer);
    task.await.unwrap();
}

/// Everything the API reads, as text to compare.
async fn read(pool: &Pool) -> Vec<String> {
    let all = jobs::list(pool, &jobs::JobFilter { limit: 1000, ..Default::default() }).await.unwrap();
    let mut out = vec![format!("{all:?}")];
    for job in &all {
        out.push(format!("{:?}", jobs::history(pool, job.id).await.unwrap()));
    }
    out.push(format!("{:?}", locations::list(pool, None).await.unwrap()));
    out.push(format!(
        "{:?}",
        alarms::list(pool, &AlarmFilter { limit: 100, ..Default::default() }).await.unwrap()
    ));
    out.push(format!("{:?}", events::after(pool, 0, 10_000).await.unwrap()));
    out.push(format!("{:?}", controls::paused(pool).await.unwrap()));
    out.push(format!("{:?}", controls::audit(pool, None, 100).await.unwrap()));
    out.push(format!("{:?}", store::counts::load(pool).await.unwrap()));
    out.push(format!("{:?}", webhooks::rows(pool).await.unwrap()));
    out.push(format!("{:?}", webhooks::deliveries(pool, "wms", None, 10).await.unwrap()));
    out
}

#[tokio::test]
async fn a_store_with_history_copies_to_postgres_and_back_unchanged() {
    let (sqlite, from, _dir) = open(Engine::Sqlite).await;
    site(&sqlite).await;
    let before = read(&sqlite).await;
    assert!(
        before[0].contains("Completed") && before[0].contains("Cancelled") && before[0].contains("Queued")
    );
    let (postgres, to, _) = open(Engine::Postgres).await;
    let copied = store::copy::copy(&from, &to).await.unwrap();
    assert_eq!(copied[0], ("jobs", 12));
    assert_eq!(read(&postgres).await, before, "the copy on PostgreSQL reads the same");

    // The copy goes on where the original stopped: the next id and event number follow.
    let (writer, task) = Writer::start(&postgres, 64, 64, Hooks::default()).await.unwrap();
    let next = writer.submit(vec![light("after", 1)]).await.unwrap();
    assert!(
        matches!(&next[0], Outcome::Created { job, .. } if job.id == 13 && job.state == JobState::Queued)
    );
    drop(writer);
    task.await.unwrap();
    let (_, last) = events::bounds(&sqlite).await.unwrap();
    assert_eq!(events::bounds(&postgres).await.unwrap().1, last + 1);

    // A copy never merges into a database that holds a store.
    let refused = store::copy::copy(&from, &to).await.unwrap_err();
    assert!(refused.to_string().contains("already holds"), "{refused}");

    // And back to a new SQLite file.
    let (back, again, _dir2) = open(Engine::Sqlite).await;
    back.close().await;
    store::copy::copy(&to, &again).await.unwrap();
    let back = store::open(&again, std::time::Duration::from_secs(5)).await.unwrap();
    assert_eq!(read(&back).await, read(&postgres).await, "PostgreSQL to SQLite reads the same");
}

/// More rows than a page (5,000) in every large table: each page starts after the last
/// key of the one before, and the copy holds every row once.
#[tokio::test]
async fn a_store_of_several_pages_copies_every_row_once() {
    use rackd::domain::JobState;
    use rackd::store::import::{self, Ended};
    let (sqlite, from, _dir) = open(Engine::Sqlite).await;
    let jobs: Vec<Ended> = (1..=12_001i64)
        .map(|id| {
            let new = light(&format!("P-{id}"), 1);
            let mut job = new.accepted(id, id);
            job.state = JobState::Completed;
            let history =
                vec![(JobState::Queued, "accepted".into(), id), (JobState::Completed, "done".into(), id)];
            Ended { request: new.canonical(), job, history }
        })
        .collect();
    import::ended_jobs(&sqlite, &jobs).await.unwrap();
    let (postgres, to, _) = open(Engine::Postgres).await;
    let copied = store::copy::copy(&from, &to).await.unwrap();
    assert!(copied.contains(&("jobs", 12_001)) && copied.contains(&("job_history", 24_002)), "{copied:?}");
    let sums = "SELECT COUNT(*), CAST(SUM(id) AS BIGINT), (SELECT COUNT(DISTINCT job_id) FROM job_history) FROM jobs";
    let a: Vec<(i64, i64, i64)> = super::rows(&sqlite, sums).await;
    let b: Vec<(i64, i64, i64)> = super::rows(&postgres, sums).await;
    assert_eq!(a, [(12_001, 12_001 * 12_002 / 2, 12_001)]);
    assert_eq!(b, a);
}
