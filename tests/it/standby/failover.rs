//! Failover under load, end to end: two `rackd serve` processes in a cluster on one
//! PostgreSQL database drive a simulated shelf PLC and a simulated stacker crane that
//! outlive them (they run in this test process). Jobs are posted to both nodes while the
//! active node is killed (SIGKILL, no goodbye) and restarted at once, `RACKD_FAILOVER_KILLS`
//! times (default 3).
//!
//! It proves that failover is safe and prompt: the restarted node comes back as a standby;
//! a standby takes over no sooner than lease + margin after the dead node's last renewal,
//! and dispatches within a few seconds of it; every job still completes, exactly once; no
//! task reaches a machine twice; neither simulator sees a breach of its interface. It
//! prints each takeover time ("last lease renewal to first dispatch by the new node") and
//! their p50/p99. A webhook subscription delivers every `job.*` event throughout, to a
//! receiver that fails a fifth of calls and is slow around each kill: each event reaches it
//! at least once, in order, and the stored cursor never passes one it did not acknowledge.
//! The subscription is new, and a new one starts from the newest event when its deliverer
//! first runs (on the first active node, once it drives): the first job is posted only
//! after that, so that every `job.*` event is the subscription's to deliver.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use rackd::cli::demo;
use rackd::config::devices::CraneConfig;
use rackd::config::{ClusterConfig, Config};
use rackd::domain::time::now_ms;
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};
use rackd::store::cluster::{self, LEASE, LeaseRow};
use serde_json::{Value, json};
use sqlx::PgPool;
use tokio::time::sleep;

use crate::support::eventually;
use crate::support::node::Node;
use crate::support::receiver::{Mode, Receiver};

const LEASE_MS: i64 = 1000;
/// The default margin: a fifth of the lease.
const MARGIN_MS: i64 = LEASE_MS / 5;
/// Room for a loaded 2-core machine: the new node starts driving (queues, devices, their
/// reconciliation) before it dispatches.
const SLACK_MS: i64 = 5000;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn killing_the_active_node_loses_no_job_and_repeats_no_task() {
    let kills: usize = std::env::var("RACKD_FAILOVER_KILLS").map_or(3, |k| k.parse().expect("a number"));
    let url = crate::support::postgres::database().await;
    let (shelf, crane) = machines().await;
    let receiver = Receiver::start().await;
    // Between the kills a receiver that fails a fifth of calls; around each, a slow one.
    let (flaky, slow) = (
        Mode { fail: 0.2, ..Mode::default() },
        Mode { delay: Duration::from_millis(300), ..Mode::default() },
    );
    receiver.set(flaky.clone());
    let dir = tempfile::tempdir().unwrap();
    let mut nodes: Vec<Node> = ["a", "b"]
        .iter()
        .map(|n| Node::new(dir.path(), n, &config(n, &url, &shelf, &crane, &receiver)))
        .collect();
    let http = reqwest::Client::builder().timeout(Duration::from_secs(5)).build().unwrap();
    nodes.iter_mut().for_each(Node::start);
    // Where each node listens since its last start (a port of its own choosing each time).
    let mut urls: Vec<String> = nodes.iter().map(|n| n.url.clone()).collect();
    for node in &nodes {
        healthy(&http, node).await;
    }
    let db = PgPool::connect(&url).await.unwrap();
    let mut lease = eventually("a lease", Duration::from_secs(15), async || {
        cluster::read(&db, LEASE).await.unwrap().ok_or("none")
    })
    .await;
    let start = subscribed(&db).await;

    let (mut mix, mut posted) = (Mix::default(), Vec::new());
    for i in 0..24 {
        posted.push(mix.post(&http, &urls, i % 2).await);
    }
    let mut takeovers = Vec::new();
    for round in 1..=kills {
        // Each kill at another point of the crane's cycle.
        sleep(Duration::from_millis(300 * (round as u64 % 4))).await;
        crane_busy(&db).await;
        receiver.set(slow.clone());
        let active = nodes.iter().position(|n| n.name == lease.holder).unwrap();
        let watch = tokio::spawn(next_term(db.clone(), lease));
        nodes[active].kill();
        let killed_at = now_ms(); // nothing it stamped comes after this
        nodes[active].start();
        urls[active] = nodes[active].url.clone();
        for _ in 0..4 {
            posted.push(mix.post(&http, &urls, 1 - active).await);
        }
        back_as_standby(&db, &nodes[active].name, killed_at).await;
        let (last, new) = watch.await.unwrap();
        let took = first_dispatch_after(&db, killed_at).await - last.renewed_at;
        eprintln!("failover {round}: {} -> {} (epoch {}): {took} ms", last.holder, new.holder, new.epoch);
        assert!(took >= LEASE_MS + MARGIN_MS, "takeover {round} before the lease ran out: {took} ms");
        assert!(took < LEASE_MS + MARGIN_MS + SLACK_MS, "takeover {round} took {took} ms");
        takeovers.push(took);
        receiver.set(flaky.clone());
        cursor_is_acknowledged(&db, &receiver).await;
        lease = new;
        healthy(&http, &nodes[active]).await;
        for i in 0..12 {
            posted.push(mix.post(&http, &urls, i % 2).await);
        }
    }

    let open =
        "SELECT id, state FROM jobs WHERE state NOT IN ('completed', 'failed', 'cancelled') ORDER BY id";
    // The crane takes about a second a job, and half the jobs are the crane's.
    eventually("every job to end", Duration::from_secs(30 + posted.len() as u64), async || {
        let open: Vec<(i64, String)> = sqlx::query_as(open).fetch_all(&db).await.unwrap();
        if open.is_empty() { Ok(()) } else { Err(format!("still open: {open:?}")) }
    })
    .await;
    let wanted: Vec<i64> = sqlx::query_scalar("SELECT seq FROM events WHERE type LIKE 'job.%' ORDER BY seq")
        .fetch_all(&db)
        .await
        .unwrap();
    assert!(wanted.iter().all(|seq| *seq > start), "job events before the subscription began at {start}");
    crate::webhooks::every_event_acked(&receiver, &wanted).await;
    cursor_is_acknowledged(&db, &receiver).await;
    receiver.check("wms", "job.");
    for node in &mut nodes {
        assert!(node.running(), "node {} exited", node.name);
    }
    every_job_completed_once(&db, posted.len()).await;
    let kinds: Vec<(String, i64)> =
        sqlx::query_as("SELECT kind, COUNT(*) FROM alarms GROUP BY kind").fetch_all(&db).await.unwrap();
    let count = |kind: &str| kinds.iter().find(|(k, _)| k == kind).map_or(0, |(_, n)| *n);
    assert_eq!(count("memory_lost"), 0, "a takeover is no power cycle: {kinds:?}");
    assert_eq!(count("takeover"), kills as i64, "one takeover alarm per takeover: {kinds:?}");
    crate::support::machines::each_task_once_and_no_breach(&shelf, &crane, &posted);

    takeovers.sort_unstable();
    let pick = |q: f64| takeovers[((takeovers.len() - 1) as f64 * q).round() as usize];
    eprintln!(
        "takeover (last renewal to first dispatch), lease {LEASE_MS} ms + margin {MARGIN_MS} ms: {takeovers:?} ms; \
         p50 {} ms, p99 {} ms; {} jobs",
        pick(0.5),
        pick(0.99),
        posted.len()
    );
}

/// The simulators, fast (a shelf task in 300 ms, a crane transfer in 16 x 50 ms), the shelf
/// with 4 slots so that its work queues up in rackd.
async fn machines() -> (ShelfSim, CraneSim) {
    let shelf = ShelfSimOptions { task_time: Duration::from_millis(300), slots: 4, ..Default::default() };
    let crane = CraneSimOptions { step: Duration::from_millis(50), ..Default::default() };
    let shelf = ShelfSim::start("127.0.0.1:0", shelf).await.unwrap();
    (shelf, CraneSim::start("127.0.0.1:0", crane).await.unwrap())
}

/// Waits until the subscription has begun: its deliverer, on the node that won the lease,
/// stored its row with its first cursor (the newest event then), which it returns. The lease
/// row alone is too early: the winner writes it, then starts driving (the queues, the
/// devices, then the deliverers), and a job posted meanwhile (any node takes jobs in) comes
/// before the subscription's first cursor, never to be delivered, as a new subscription's
/// rule says (`service::webhooks`).
async fn subscribed(db: &PgPool) -> i64 {
    let sql = "SELECT cursor FROM webhooks WHERE name = 'wms'";
    eventually("the subscription to begin", Duration::from_secs(30), async || {
        sqlx::query_scalar::<_, i64>(sql).fetch_optional(db).await.unwrap().ok_or("no row yet")
    })
    .await
}

/// The stored cursor passes no `job.*` event the receiver has not acknowledged.
async fn cursor_is_acknowledged(db: &PgPool, receiver: &Receiver) {
    let sql = "SELECT cursor FROM webhooks WHERE name = 'wms'";
    let Some(cursor) = sqlx::query_scalar::<_, i64>(sql).fetch_optional(db).await.unwrap() else { return };
    let passed: Vec<i64> = sqlx::query_scalar("SELECT seq FROM events WHERE type LIKE 'job.%' AND seq <= $1")
        .bind(cursor)
        .fetch_all(db)
        .await
        .unwrap();
    crate::webhooks::assert_cursor_acknowledged(cursor, &passed, receiver);
}

/// A node's configuration: the demo layout, its two devices on the simulators, the cluster,
/// a webhook subscription to `receiver`.
fn config(node: &str, database: &str, shelf: &ShelfSim, crane: &CraneSim, receiver: &Receiver) -> Config {
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    config.database.url = Some(database.to_owned());
    config.cluster = Some(ClusterConfig {
        node: node.into(),
        lease_ms: LEASE_MS as u64,
        margin_ms: None,
        url: None,
        ca_file: None,
    });
    let mut shelf1 = demo::shelf_device(shelf, "shelf1", &shelf.local_addr().unwrap().to_string(), vec![1]);
    shelf1.poll_ms = 100;
    let mut crane1 = CraneConfig::new("crane1", &crane.local_addr().to_string(), vec![2]);
    crane1.poll_ms = 100;
    config.devices = vec![shelf1.into(), crane1.into()];
    let mut webhook = crate::webhooks::api::subscription(receiver);
    webhook.timeout_ms = 1000;
    config.webhooks = vec![webhook];
    config
}

/// The jobs posted, on each aisle in turn: a store into a free near place, a light (shelf)
/// or an empty travel (crane), then the retrieve of the oldest box stored.
#[derive(Default)]
struct Mix {
    n: u16,
    stored: [VecDeque<Value>; 2],
}

impl Mix {
    fn next(&mut self) -> (u16, Value) {
        let (aisle, k) = (1 + self.n % 2, self.n / 2);
        self.n += 1;
        // Each k < 200 its own place: row, bay, level.
        let at = |level| json!({"aisle": aisle, "row": 1 + k % 2, "bay": 1 + k / 2 % 10, "level": level, "position": 1});
        let stored = &mut self.stored[usize::from(aisle - 1)];
        let mut job = match k % 3 {
            0 => {
                let to = at(1 + k / 20 % 5);
                stored.push_back(to.clone());
                json!({"kind": "store", "barcode": format!("BOX-{}", self.n), "to": to})
            }
            1 if aisle == 1 => {
                json!({"kind": "light", "location": at(6), "color": "green", "on": k % 2 == 0})
            }
            1 => json!({"kind": "travel", "to": at(8)}),
            _ => json!({"kind": "retrieve", "from": stored.pop_front().expect("stored two jobs ago")}),
        };
        job["reference"] = json!(format!("failover-{}", self.n));
        (aisle, job)
    }

    /// Posts the next job to node `first` (to the other while it does not answer; the same
    /// reference makes a retry of a job already taken answer that job). Its id and aisle.
    async fn post(&mut self, http: &reqwest::Client, urls: &[String], first: usize) -> (i64, u16) {
        let (aisle, job) = self.next();
        let mut urls = urls.iter().cycle().skip(first);
        eventually("a node to take a job", Duration::from_secs(20), async || {
            let url = urls.next().unwrap();
            let answer = http.post(format!("{url}/api/v1/jobs")).json(&job).send().await;
            let answer = answer.map_err(|e| format!("{url}: {e}"))?;
            let status = answer.status().as_u16();
            let body: Value = answer.json().await.unwrap_or_default();
            assert!(!(400..500).contains(&status), "{url} refused {job}: {status} {body}");
            body["id"].as_i64().map(|id| (id, aisle)).ok_or(format!("{url}: {status} {body}"))
        })
        .await
    }
}

async fn healthy(http: &reqwest::Client, node: &Node) {
    let url = format!("{}/healthz", node.url);
    let what = format!("node {} to answer", node.name);
    eventually(&what, Duration::from_secs(30), async || http.get(&url).send().await?.error_for_status())
        .await;
}

/// Waits until the crane has a job under way and more queued behind it.
async fn crane_busy(db: &PgPool) {
    let sql = "SELECT COUNT(*) FILTER (WHERE state IN ('dispatched', 'running')), \
               COUNT(*) FILTER (WHERE state = 'queued') FROM jobs WHERE device = 'crane1'";
    eventually("the crane to be busy", Duration::from_secs(30), async || {
        let (under_way, queued): (i64, i64) = sqlx::query_as(sql).fetch_one(db).await.unwrap();
        if under_way > 0 && queued > 0 { Ok(()) } else { Err((under_way, queued)) }
    })
    .await
}

/// Polls the lease every 20 ms until a term after `old`'s begins: the old term's last row
/// (its last renewal) and the new term's first.
async fn next_term(db: PgPool, old: LeaseRow) -> (LeaseRow, LeaseRow) {
    // Not `eventually`: this runs in a task of its own, and a future that calls an async
    // closure through `AsyncFnMut` is not known to be `Send`.
    let deadline = Instant::now() + Duration::from_secs(15);
    let mut last = old;
    loop {
        let row = cluster::read(&db, LEASE).await.unwrap().expect("the lease row");
        if row.epoch > last.epoch {
            return (last, row);
        }
        assert!(Instant::now() < deadline, "no takeover within 15 s: {row:?}");
        last = row;
        sleep(Duration::from_millis(20)).await;
    }
}

/// Waits until the process of `node` started after `since` (ms) tells the cluster of
/// itself, and checks that it came back as a standby.
async fn back_as_standby(db: &PgPool, node: &str, since: i64) {
    let sql = "SELECT role, started_at FROM cluster_nodes WHERE name = $1";
    let role = eventually("the restarted node", Duration::from_secs(15), async || {
        let (role, started_at): (String, i64) = sqlx::query_as(sql).bind(node).fetch_one(db).await.unwrap();
        if started_at >= since { Ok(role) } else { Err(started_at) }
    })
    .await;
    assert_eq!(role, "standby", "node {node} restarted as {role}");
}

/// The time (ms) of the first dispatch after `after` (ms).
async fn first_dispatch_after(db: &PgPool, after: i64) -> i64 {
    let sql = "SELECT MIN(at) FROM job_history WHERE state = 'dispatched' AND at > $1";
    eventually("a dispatch after the kill", Duration::from_secs(15), async || {
        sqlx::query_scalar::<_, Option<i64>>(sql).bind(after).fetch_one(db).await.unwrap().ok_or("none")
    })
    .await
}

/// Every job (the posted ones and no other) completed, with one `completed` entry in its
/// history and no `failed` or `cancelled` one.
async fn every_job_completed_once(db: &PgPool, posted: usize) {
    let jobs: Vec<(i64, String, Option<String>)> =
        sqlx::query_as("SELECT id, state, failure_text FROM jobs ORDER BY id").fetch_all(db).await.unwrap();
    assert_eq!(jobs.len(), posted, "only the posted jobs exist");
    let not_completed: Vec<_> = jobs.iter().filter(|(_, state, _)| state != "completed").collect();
    assert!(not_completed.is_empty(), "jobs that did not complete: {not_completed:?}");
    crate::support::machines::one_completed_ending_each(db, posted).await;
}
