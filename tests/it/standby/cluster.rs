//! The cluster lease on a real PostgreSQL: one active node at a time, takeover after the
//! lease when the active node dies (its loop aborted without a word, as under SIGKILL),
//! at once when it lets go, fencing of the old epoch, and a partition (a proxy that stops
//! forwarding) making the active node stop driving before the standby starts.

use std::sync::Arc;
use std::time::Duration;

use rackd::service::cluster::lease::Timing;
use rackd::service::cluster::{LEASE, Leadership, Role};
use rackd::store::{Database, Pool, cluster};
use sqlx::{Connection, PgPool};
use tokio::time::Instant;

use crate::support::proxy::Proxy;

const TIMING: Timing = Timing { lease: Duration::from_millis(600), margin: Duration::from_millis(150) };

async fn pool(url: &str) -> PgPool {
    pool_with(url, Duration::from_secs(5)).await
}

/// A pool whose sessions the server lets idle in a transaction for a minute
/// (`idle_in_transaction_session_timeout` is the store's busy timeout), for a test that
/// holds a fenced transaction open while it watches others wait or not: at the 5 s of
/// [`pool`], a slow machine could see the server end that transaction, and its locks with
/// it, in the middle of the test.
async fn patient_pool(url: &str) -> PgPool {
    pool_with(url, Duration::from_secs(60)).await
}

async fn pool_with(url: &str, busy_timeout: Duration) -> PgPool {
    match rackd::store::open(&Database::Postgres(url.to_owned()), busy_timeout).await.unwrap() {
        Pool::Postgres(p) => p,
        Pool::Sqlite(_) => unreachable!(),
    }
}

/// Waits until `node` is active and returns its epoch and when it became so.
async fn active(node: &mut Leadership, within: Duration) -> (i64, Instant) {
    let deadline = Instant::now() + within;
    loop {
        if let Role::Active { epoch } = *node.role.borrow_and_update() {
            return (epoch, Instant::now());
        }
        tokio::time::timeout_at(deadline, node.role.changed())
            .await
            .unwrap_or_else(|_| panic!("no node became active within {within:?}"))
            .unwrap();
    }
}

#[tokio::test]
async fn one_node_is_active_and_a_standby_takes_over_when_it_dies() {
    let url = crate::support::postgres::database().await;
    let db = pool(&url).await;
    let mut a = Leadership::start(db.clone(), "a".into(), TIMING);
    let (epoch, _) = active(&mut a, Duration::from_secs(5)).await;
    assert_eq!(epoch, 1);
    let mut b = Leadership::start(db.clone(), "b".into(), TIMING);
    tokio::time::sleep(TIMING.lease * 3).await;
    assert_eq!(*b.role.borrow(), Role::Standby, "a live active node keeps its lease");
    assert_eq!(a.gate.may_drive(), Some(1));
    assert_eq!(b.gate.may_drive(), None);

    // a dies without a word: b takes over once the lease has stood still for lease + margin.
    let died = Instant::now();
    a.abort();
    let (epoch, at) = active(&mut b, Duration::from_secs(5)).await;
    assert_eq!(epoch, 2, "the epoch grows at every takeover");
    let took = at - died;
    // b waits lease + margin from when it saw a's last renewal, and that renewal was sent
    // at most one renewal period before a died (a is aborted between renewals, at any point).
    let earliest = TIMING.lease + TIMING.margin - TIMING.renew_every();
    assert!(took >= earliest, "not before a's last renewal ran out: {took:?}, earliest {earliest:?}");
    // lease + margin after a's last renewal, plus a standby poll; a second of slack for a
    // loaded machine (the figures come from the cluster benchmark, not from here).
    assert!(took < TIMING.lease + TIMING.margin + Duration::from_secs(1), "took {took:?}");
    assert_eq!(b.gate.may_drive(), Some(2));

    // The old epoch can neither renew nor commit under the fence; the new one can.
    assert!(!cluster::renew(&db, LEASE, "a", 1).await.unwrap());
    let mut conn = db.acquire().await.unwrap();
    let mut tx = conn.begin().await.unwrap();
    assert!(!cluster::fence(&mut tx, LEASE, 1).await.unwrap());
    assert!(cluster::fence(&mut tx, LEASE, 2).await.unwrap());
    tx.commit().await.unwrap();
    drop(conn);

    // b lets go: c takes over at once, without waiting out the lease.
    let mut c = Leadership::start(db.clone(), "c".into(), TIMING);
    tokio::time::sleep(TIMING.lease).await;
    let released = Instant::now();
    b.release(&db, "b").await.unwrap();
    let (epoch, at) = active(&mut c, Duration::from_secs(5)).await;
    assert_eq!(epoch, 3);
    assert!(at - released < TIMING.lease, "a released lease is taken at once: {:?}", at - released);
    let row = cluster::read(&db, LEASE).await.unwrap().unwrap();
    assert_eq!((row.holder.as_str(), row.epoch), ("c", 3));
    c.abort();
}

#[tokio::test]
async fn a_takeover_waits_for_a_write_committed_under_the_old_epoch() {
    let url = crate::support::postgres::database().await;
    let db = patient_pool(&url).await;
    assert_eq!(cluster::take(&db, LEASE, "a", None).await.unwrap(), Some(1));
    assert_eq!(cluster::take(&db, LEASE, "b", None).await.unwrap(), None, "one first claim only");
    let seen = cluster::read(&db, LEASE).await.unwrap().unwrap();
    // a's dispatch transaction holds the fence while b tries to take over.
    let mut conn = db.acquire().await.unwrap();
    let mut tx = conn.begin().await.unwrap();
    assert!(cluster::fence(&mut tx, LEASE, 1).await.unwrap());
    let take = tokio::spawn({
        let db = db.clone();
        async move { cluster::take(&db, LEASE, "b", Some(&seen)).await.unwrap() }
    });
    takeover_waits_on_a_lock(&db).await;
    assert!(!take.is_finished(), "the takeover waits for the fenced transaction");
    tx.commit().await.unwrap();
    assert_eq!(take.await.unwrap(), Some(2));
    // A takeover over a row that has changed since it was watched fails.
    let stale = cluster::LeaseRow { holder: "a".into(), epoch: 1, beat: 0, released: false, renewed_at: 0 };
    assert_eq!(cluster::take(&db, LEASE, "c", Some(&stale)).await.unwrap(), None);
}

/// Waits until a takeover on this test's database waits for a row lock (the fence of an
/// open transaction), as the server's own view of its sessions tells.
async fn takeover_waits_on_a_lock(db: &PgPool) {
    let sql = "SELECT COUNT(*) FROM pg_stat_activity WHERE datname = current_database() \
               AND wait_event_type = 'Lock' AND query LIKE '%WITH watched AS%'";
    crate::support::eventually("the takeover to wait for a row lock", Duration::from_secs(10), async || {
        let waiting: i64 = sqlx::query_scalar(sql).fetch_one(db).await.unwrap();
        (waiting == 1).then_some(())
    })
    .await;
}

/// The fence locks the lease row `FOR KEY SHARE` (`store::cluster`'s module doc): an open
/// fenced write holds back neither the holder's renewals nor its release, while the
/// takeover after them still waits for it, and a fence after the takeover refuses the old
/// epoch. (Under `FOR SHARE`, a renewal waited for the writer's transaction, which could
/// wait on the other node's writer: a loaded failover test saw one renewal take 983 ms of
/// a 1000 ms lease.)
#[tokio::test]
async fn a_renewal_passes_an_open_fenced_write_and_a_takeover_still_waits_for_it() {
    let url = crate::support::postgres::database().await;
    let db = patient_pool(&url).await;
    let soon = Duration::from_secs(5);
    assert_eq!(cluster::take(&db, LEASE, "a", None).await.unwrap(), Some(1));
    let mut conn = db.acquire().await.unwrap();
    let mut tx = conn.begin().await.unwrap();
    assert!(cluster::fence(&mut tx, LEASE, 1).await.unwrap());
    for _ in 0..3 {
        let renewed = tokio::time::timeout(soon, cluster::renew(&db, LEASE, "a", 1)).await;
        assert!(renewed.expect("a renewal is not held back by an open fenced write").unwrap());
    }
    let seen = cluster::read(&db, LEASE).await.unwrap().unwrap();
    assert_eq!((seen.epoch, seen.beat), (1, 3));
    // The row a's transaction locked has a new version by now: the takeover, which locks
    // that newest version, still waits for the transaction.
    let take = tokio::spawn({
        let db = db.clone();
        async move { cluster::take(&db, LEASE, "b", Some(&seen)).await.unwrap() }
    });
    takeover_waits_on_a_lock(&db).await;
    assert!(!take.is_finished(), "the takeover waits for the fenced transaction");
    tx.commit().await.unwrap();
    assert_eq!(take.await.unwrap(), Some(2));
    let mut tx = conn.begin().await.unwrap();
    assert!(!cluster::fence(&mut tx, LEASE, 1).await.unwrap(), "the old epoch is fenced off");
    tx.rollback().await.unwrap();

    // A release passes the holder's open fenced write too; the takeover it allows at once
    // still waits for that write.
    let mut tx = conn.begin().await.unwrap();
    assert!(cluster::fence(&mut tx, LEASE, 2).await.unwrap());
    let released = tokio::time::timeout(soon, cluster::release(&db, LEASE, "b", 2)).await;
    assert!(released.expect("a release is not held back by an open fenced write").unwrap());
    let seen = cluster::read(&db, LEASE).await.unwrap().unwrap();
    assert!(seen.released);
    let take = tokio::spawn({
        let db = db.clone();
        async move { cluster::take(&db, LEASE, "c", Some(&seen)).await.unwrap() }
    });
    takeover_waits_on_a_lock(&db).await;
    assert!(!take.is_finished(), "the takeover of a released lease waits for the fenced transaction");
    tx.commit().await.unwrap();
    assert_eq!(take.await.unwrap(), Some(3));
    let mut tx = conn.begin().await.unwrap();
    assert!(!cluster::fence(&mut tx, LEASE, 2).await.unwrap(), "the released epoch is fenced off");
    assert!(cluster::fence(&mut tx, LEASE, 3).await.unwrap());
    tx.commit().await.unwrap();
}

/// A node cut off while a dispatch write holds the lease row under the fence (the
/// connection stays open, nothing gets through): the server ends that transaction after the
/// store's busy timeout, so the standby's takeover goes through instead of waiting for ever.
#[tokio::test]
async fn a_fenced_transaction_cut_off_mid_way_does_not_hold_the_lease_for_ever() {
    let url = crate::support::postgres::database().await;
    let db = pool(&url).await;
    let (proxy, proxied) = Proxy::to_postgres(&url).await;
    let cut_off =
        match rackd::store::open(&Database::Postgres(proxied), Duration::from_secs(1)).await.unwrap() {
            Pool::Postgres(p) => p,
            Pool::Sqlite(_) => unreachable!(),
        };
    assert_eq!(cluster::take(&cut_off, LEASE, "a", None).await.unwrap(), Some(1));
    let seen = cluster::read(&db, LEASE).await.unwrap().unwrap();
    let mut tx = cut_off.begin().await.unwrap();
    assert!(cluster::fence(&mut tx, LEASE, 1).await.unwrap());
    proxy.block();
    let started = Instant::now();
    let took =
        tokio::time::timeout(Duration::from_secs(20), cluster::take(&db, LEASE, "b", Some(&seen))).await;
    assert_eq!(took.expect("the takeover is not held for ever").unwrap(), Some(2));
    assert!(started.elapsed() >= Duration::from_millis(500), "it waited for the fenced write first");
    drop(tx);
}

#[tokio::test]
async fn a_partitioned_active_node_stops_driving_before_the_standby_starts() {
    let url = crate::support::postgres::database().await;
    let db = pool(&url).await;
    let (proxy, proxied) = Proxy::to_postgres(&url).await;
    let cut_off = pool(&proxied).await;
    let mut a = Leadership::start(cut_off, "a".into(), TIMING);
    active(&mut a, Duration::from_secs(5)).await;
    let mut b = Leadership::start(db.clone(), "b".into(), TIMING);
    tokio::time::sleep(TIMING.lease * 2).await;

    proxy.block();
    let cut = Instant::now();
    // Note the last instant a's gate is seen open. Seen late under load, it is only earlier.
    let last_open = tokio::spawn({
        let gate = a.gate.clone();
        async move {
            let mut last = Instant::now();
            while gate.may_drive().is_some() {
                last = Instant::now();
                tokio::time::sleep(Duration::from_millis(1)).await;
            }
            last
        }
    });
    // No renewal gets through after the cut: a stops driving a lease after it at the latest.
    tokio::time::sleep_until(cut + TIMING.lease + Duration::from_millis(1)).await;
    assert_eq!(a.gate.may_drive(), None, "a stops driving within its lease of the cut");
    let (epoch, started) = active(&mut b, Duration::from_secs(5)).await;
    assert_eq!(epoch, 2);
    let last_open = last_open.await.unwrap();
    assert!(
        last_open < started,
        "a last drove {:?} after the cut, b started {:?} after it",
        last_open - cut,
        started - cut
    );
    a.abort();
    b.abort();
}

/// A travel job with a reference.
fn travel(reference: String, n: u16) -> rackd::domain::NewJob {
    use rackd::domain::{JobSpec, Location, NewJob, Priority};
    NewJob {
        spec: JobSpec::Travel { to: Location { aisle: 1, row: 1, bay: 1 + n % 10, level: 1, position: 1 } },
        reference: Some(reference),
        priority: Priority::default(),
        barcode: None,
        device: None,
        serves: None,
        terms: Default::default(),
    }
}

#[tokio::test]
async fn two_nodes_writers_on_one_database_number_jobs_and_events_without_clash_or_gap() {
    use rackd::store::writer::{Hooks, Writer};
    let url = crate::support::postgres::database().await;
    let (a, b) = (pool(&url).await, pool(&url).await);
    let mut writers = Vec::new();
    for p in [a.clone(), b] {
        let (w, _) = Writer::start_shared(&Pool::Postgres(p), 64, 1024, Hooks::default()).await.unwrap();
        writers.push(w);
    }
    let job = |node: usize, n: u16| travel(format!("node{node}-{n}"), n);
    let mut tasks = Vec::new();
    for (node, w) in writers.iter().enumerate() {
        for n in 0..100u16 {
            let w = w.clone();
            tasks.push(tokio::spawn(async move { w.submit(vec![job(node, n), job(node, n + 1000)]).await }));
        }
    }
    for t in tasks {
        t.await.unwrap().expect("every submission commits");
    }
    let ids: Vec<i64> = sqlx::query_scalar("SELECT id FROM jobs ORDER BY id").fetch_all(&a).await.unwrap();
    assert_eq!(ids, (1..=400).collect::<Vec<i64>>(), "400 jobs, ids unique and gapless");
    let seqs: Vec<i64> =
        sqlx::query_scalar("SELECT seq FROM events ORDER BY seq").fetch_all(&a).await.unwrap();
    assert!(seqs.len() >= 400, "an event per job at least: {}", seqs.len());
    assert_eq!(seqs, (1..=seqs.len() as i64).collect::<Vec<i64>>(), "the event log is gapless");
}

#[tokio::test]
async fn a_fenced_writer_commits_only_under_the_epoch_that_holds_the_lease() {
    use rackd::store::writer::{Change, Hooks, WriteError, Writer};
    let url = crate::support::postgres::database().await;
    let db = pool(&url).await;
    let (writer, _) =
        Writer::start_shared(&Pool::Postgres(db.clone()), 64, 1024, Hooks::default()).await.unwrap();
    let job = |n: u16| travel(format!("job-{n}"), n);
    assert_eq!(cluster::take(&db, LEASE, "a", None).await.unwrap(), Some(1));
    let under = |epoch: Option<i64>| writer.fenced(Arc::new(move || epoch));
    let a = under(Some(1));
    writer.submit((0..4).map(job).collect()).await.unwrap();
    a.change(1, Change::cancel_queued()).await.expect("epoch 1 holds the lease");
    assert!(matches!(under(None).change(2, Change::cancel_queued()).await, Err(WriteError::Fenced(None))));

    // b takes over: a's epoch can no longer commit, in a group of its own or mixed with
    // unfenced submissions, which commit.
    let seen = cluster::read(&db, LEASE).await.unwrap().unwrap();
    assert_eq!(cluster::take(&db, LEASE, "b", Some(&seen)).await.unwrap(), Some(2));
    let mut tasks = Vec::new();
    for n in 0..20u16 {
        let (a, w) = (a.clone(), writer.clone());
        tasks.push(tokio::spawn(async move {
            let stale = a.change(2 + i64::from(n % 3), Change::cancel_queued()).await;
            assert!(matches!(stale, Err(WriteError::Fenced(Some(1)))), "{stale:?}");
            w.submit(vec![job(100 + n)]).await.expect("unfenced submissions commit");
        }));
    }
    for t in tasks {
        t.await.unwrap();
    }
    let states: Vec<(i64, String)> =
        sqlx::query_as("SELECT id, state FROM jobs WHERE id <= 4 ORDER BY id").fetch_all(&db).await.unwrap();
    let cancelled: Vec<i64> = states.iter().filter(|(_, s)| s == "cancelled").map(|(id, _)| *id).collect();
    assert_eq!(cancelled, [1], "only the change under the lease's epoch was written: {states:?}");
    let count: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM jobs").fetch_one(&db).await.unwrap();
    assert_eq!(count, 24);
    under(Some(2)).change(2, Change::cancel_queued()).await.expect("epoch 2 holds it now");
}
