//! The hot standby through database failovers (issue 53): two `rackd serve` processes in a
//! cluster drive the demo site's shelf and crane simulators (in this test process), both on
//! one `database.url` listing a PostgreSQL primary and its synchronous streaming replica
//! (`support::pg_owned`) with `target_session_attrs=read-write`. The lease lives in that
//! database, and fails over with it. While a WMS posts jobs to both nodes in turn
//! (`support::flow`), three failovers, each a crash of the primary (`-m immediate`) and the
//! promotion of the replica, and each of another kind ([`Failover`]):
//!
//! 1. **Under the pair**, promoted at once: shorter than the lease, it is ridden through. The
//!    active node's next renewal commits on the new primary: same holder, same epoch.
//! 2. **With the active node killed** (SIGKILL) at the crash: the standby's wait for the
//!    lease to stand still runs across the failover, and it takes over on the new primary
//!    (epoch + 1) from the row as the old primary last acknowledged it.
//! 3. **Longer than the lease**: the database stays down until the active node's log says
//!    its lease ran out (no server takes a renewal); then the promotion, and a takeover as
//!    after a partition (epoch + 1). The old active node ends its process, as it must.
//!
//! Between rounds the old primary is rebuilt as the new one's replica and made
//! synchronous; after the last there is no further failover to prepare. The test is each
//! node's supervisor: a node whose process ended (killed, or lost its lease) is started
//! again once a server takes writes, and the flow pointed at its new port.
//!
//! Checked throughout: `GET /api/v1/cluster` asked of both nodes in turn, one request at a
//! time, never shows the lease's epoch lower than one shown before, and no epoch is ever
//! reported active by two nodes. After each failover, once things settle: exactly one
//! node active, the other standing by, both seeing the same lease. At the end: every job
//! accepted with a 2xx stored once and completed once, each task reached its machine once,
//! and neither simulator saw a breach of its interface (no busy-slot write on the shelf,
//! no hand-over breach and no task refused by a busy crane): never two nodes driving. It
//! prints, for each failover, the time from the crash to a node driving again (the first
//! dispatch committed after the crash).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use rackd::cli::demo::{self, Pace};
use rackd::config::{ClusterConfig, Config};
use rackd::domain::time::now_ms;
use serde_json::Value;
use sqlx::PgPool;

use crate::store::pg_restart::every_job_completed_once;
use crate::support::eventually;
use crate::support::flow::Flow;
use crate::support::node::Node;
use crate::support::pg_owned::Owned;

/// Long enough that a failover promoted at once is ridden through on a loaded machine (a
/// renewal every 667 ms, each allowed three), short enough for a takeover in seconds.
const LEASE_MS: u64 = 2000;

/// The failovers, in order (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Failover {
    UnderThePair,
    WithTheActiveKilled,
    LongerThanTheLease,
}

const ROUNDS: [Failover; 3] =
    [Failover::UnderThePair, Failover::WithTheActiveKilled, Failover::LongerThanTheLease];

/// One failover, timed.
#[derive(Debug)]
struct Figure {
    kind: Failover,
    /// From the crash to the replica promoted (taking writes).
    down: Duration,
    /// From the crash to the first dispatch committed after it: a node driving again.
    driving: Duration,
    /// The lease before and after: (holder, epoch).
    before: (String, i64),
    after: (String, i64),
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_pair_keeps_its_fencing_through_database_failovers() {
    let started = Instant::now();
    let first = Owned::primary("rackd").await;
    let second = Owned::replica_of(&first).await;
    first.synchronous().await;
    let url = format!(
        "postgres://postgres@127.0.0.1:{},127.0.0.1:{}/rackd?target_session_attrs=read-write",
        first.port, second.port
    );
    let mut servers = [first, second];
    let mut site = Config::demo();
    let pace = Pace { task_time: Duration::from_millis(300), crane_step: Duration::from_millis(30) };
    let (shelf, crane, _tower) = demo::start_with(&mut site, pace).await.expect("the demo simulators");
    let dir = tempfile::tempdir().unwrap();
    let mut nodes: Vec<Node> =
        ["a", "b"].iter().map(|n| Node::new(dir.path(), n, &config(n, &url, &site))).collect();
    // a first, so that it is the first active node.
    start(&mut nodes[0]);
    let http = reqwest::Client::new();
    eventually("node a to be active", Duration::from_secs(20), async || {
        view(&http, &nodes[0].url).await.filter(|v| v["role"] == "active").ok_or("not yet")
    })
    .await;
    start(&mut nodes[1]);
    let cluster = Watcher::start(nodes.iter().map(|n| n.url.clone()).collect());
    let mut lease = settled(&mut nodes, &cluster, None).await;
    let flow = Flow::start(nodes.iter().map(|n| n.url.clone()).collect(), Duration::from_millis(200), "pair");
    eprintln!("ready after {:?}", started.elapsed());

    let mut primary = 0;
    let mut figures = Vec::new();
    for (round, kind) in ROUNDS.into_iter().enumerate() {
        let from = flow.count();
        eventually("two more jobs accepted", Duration::from_secs(20), async || {
            if flow.count() >= from + 2 { Ok(()) } else { Err(flow.count()) }
        })
        .await;
        let active = nodes.iter().position(|n| n.name == lease.0).expect("the holder is a node");
        let lost_before = nodes[active].log().matches(LOST).count();
        let (old, new) = pair(&mut servers, primary);
        if kind == Failover::WithTheActiveKilled {
            nodes[active].kill();
        }
        old.crash().await;
        let (crashed, crashed_ms) = (Instant::now(), now_ms());
        if kind == Failover::LongerThanTheLease {
            let node = &nodes[active];
            eventually("the active node to let its lease run out", Duration::from_secs(15), async || {
                node.log().matches(LOST).count() > lost_before
            })
            .await;
        }
        new.promote().await;
        let down = crashed.elapsed();
        if kind == Failover::LongerThanTheLease {
            // It stopped driving at its lease's end; it ends its process once its writer
            // has drained on the new primary (or after a bound), to stand by anew.
            let node = &mut nodes[active];
            eventually("the node that lost its lease to end", Duration::from_secs(15), async || {
                !node.running()
            })
            .await;
        }
        let after = settled(&mut nodes, &cluster, Some(&flow)).await;
        let db = PgPool::connect(&new.url("rackd")).await.unwrap();
        let driving =
            Duration::from_millis((first_dispatch_after(&db, crashed_ms).await - crashed_ms) as u64);
        db.close().await;
        let figure = Figure { kind, down, driving, before: lease.clone(), after: after.clone() };
        eprintln!(
            "failover {} ({:?}): promoted {} ms after the crash, a node driving {} ms after it; lease {:?} -> {:?}",
            round + 1,
            figure.kind,
            figure.down.as_millis(),
            figure.driving.as_millis(),
            figure.before,
            figure.after
        );
        match kind {
            Failover::UnderThePair => {
                assert_eq!(after, lease, "a failover shorter than the lease is ridden through")
            }
            Failover::WithTheActiveKilled | Failover::LongerThanTheLease => {
                assert_eq!(after.1, lease.1 + 1, "one takeover, on the new primary: {figure:?}")
            }
        }
        figures.push(figure);
        lease = after;
        if round + 1 < ROUNDS.len() {
            old.rebuild_from(new).await;
            new.synchronous().await;
        }
        primary = 1 - primary;
    }
    let accepted = flow.stop().await;

    let db = PgPool::connect(&servers[primary].url("rackd")).await.unwrap();
    every_job_completed_once(&db, &accepted).await;
    let posted: Vec<(i64, u16)> = accepted.iter().map(|a| (a.id, a.aisle)).collect();
    crate::support::machines::each_task_once_and_no_breach(&shelf, &crane, &posted);
    let seen = cluster.stop().await;
    let stored: i64 = sqlx::query_scalar("SELECT epoch FROM cluster_lease").fetch_one(&db).await.unwrap();
    assert_eq!(stored, lease.1, "the lease as stored at the end");
    for node in &mut nodes {
        assert!(node.running(), "node {} ended", node.name);
    }
    eprintln!(
        "{} failovers, {} jobs ({} retried), {} views of the cluster; a node driving again after the crash: {:?} ms",
        figures.len(),
        accepted.len(),
        accepted.iter().filter(|a| a.retried).count(),
        seen,
        figures.iter().map(|f| f.driving.as_millis()).collect::<Vec<_>>()
    );
    eprintln!("took {:?}", started.elapsed());
}

/// What a node logs when its lease runs out (`service::cluster::run`).
const LOST: &str = "the lease is lost";

/// A node's configuration: the demo site on the simulators, the cluster, the database.
fn config(node: &str, database: &str, site: &Config) -> Config {
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    config.database.url = Some(database.to_owned());
    config.site = site.site.clone();
    config.devices = site.devices.clone();
    config.cluster = Some(ClusterConfig {
        node: node.into(),
        lease_ms: LEASE_MS,
        margin_ms: None,
        url: None,
        ca_file: None,
    });
    config
}

/// Starts `node` (it reads its own address from its log: a blocking wait).
fn start(node: &mut Node) {
    tokio::task::block_in_place(|| node.start());
}

/// As a supervisor, starts again a node whose process ended (every node was started) (pointing the flow and the
/// watcher at its new port), and waits until exactly one node is active and both see the
/// same lease, held by it; answers it: (holder, epoch).
async fn settled(nodes: &mut [Node], cluster: &Watcher, flow: Option<&Flow>) -> (String, i64) {
    let http = reqwest::Client::builder().timeout(Duration::from_secs(2)).build().unwrap();
    eventually("exactly one node active, both seeing its lease", Duration::from_secs(30), async || {
        for (i, node) in nodes.iter_mut().enumerate() {
            if !node.running() {
                start(node);
                cluster.point(i, &node.url);
                if let Some(flow) = flow {
                    flow.point(i, &node.url);
                }
            }
        }
        let mut views = Vec::new();
        for node in nodes.iter() {
            let view = view(&http, &node.url).await.ok_or(format!("node {} does not answer", node.name))?;
            views.push(view);
        }
        let active: Vec<&Value> = views.iter().filter(|v| v["role"] == "active").collect();
        let [one] = active[..] else { return Err(format!("not one active: {views:?}")) };
        let holder = one["node"].as_str().unwrap_or_default().to_owned();
        let epoch = one["epoch"].as_i64().unwrap_or_default();
        let agreed = views.iter().all(|v| {
            v["lease"]["holder"] == holder.as_str()
                && v["lease"]["epoch"] == epoch
                && v["lease"]["released"] == false
        });
        if agreed && views.len() == 2 { Ok((holder, epoch)) } else { Err(format!("{views:?}")) }
    })
    .await
}

/// `GET /api/v1/cluster` of the node at `url`, if it answers 200.
async fn view(http: &reqwest::Client, url: &str) -> Option<Value> {
    let answer = http.get(format!("{url}/api/v1/cluster")).send().await.ok()?;
    if answer.status() != 200 {
        return None;
    }
    answer.json().await.ok()
}

/// The time (ms) of the first dispatch committed after `after` (ms).
async fn first_dispatch_after(db: &PgPool, after: i64) -> i64 {
    let sql = "SELECT MIN(at) FROM job_history WHERE state = 'dispatched' AND at > $1";
    eventually("a dispatch after the crash", Duration::from_secs(15), async || {
        sqlx::query_scalar::<_, Option<i64>>(sql).bind(after).fetch_one(db).await.unwrap().ok_or("none")
    })
    .await
}

/// The server at `primary` and the other.
fn pair(servers: &mut [Owned; 2], primary: usize) -> (&mut Owned, &mut Owned) {
    let [a, b] = servers;
    if primary == 0 { (a, b) } else { (b, a) }
}

/// Asks both nodes `GET /api/v1/cluster` in turn, one request at a time, for the whole
/// test, and checks each answer against those before: the lease's epoch never lower than
/// one shown before, and an epoch reported active by one node only.
struct Watcher {
    urls: Arc<Mutex<Vec<String>>>,
    stop: Arc<AtomicBool>,
    task: tokio::task::JoinHandle<usize>,
}

impl Watcher {
    fn start(urls: Vec<String>) -> Watcher {
        let urls = Arc::new(Mutex::new(urls));
        let stop = Arc::new(AtomicBool::new(false));
        let task = tokio::spawn(watch(urls.clone(), stop.clone()));
        Watcher { urls, stop, task }
    }

    /// Asks `url` in place of the `i`-th node's.
    fn point(&self, i: usize, url: &str) {
        self.urls.lock().unwrap()[i] = url.to_owned();
    }

    /// Stops, and answers how many views it checked (a failed check fails the test here).
    async fn stop(self) -> usize {
        self.stop.store(true, Ordering::Relaxed);
        self.task.await.expect("the cluster's views, checked")
    }
}

/// The watcher's loop. Not `eventually`: a spawned future that calls an async closure
/// through `AsyncFnMut` is not known to be `Send`.
async fn watch(urls: Arc<Mutex<Vec<String>>>, stop: Arc<AtomicBool>) -> usize {
    let http = reqwest::Client::builder().timeout(Duration::from_secs(2)).build().unwrap();
    let (mut highest, mut seen) = (0i64, 0usize);
    // Each epoch reported active, and by which node.
    let mut terms: Vec<(i64, String)> = Vec::new();
    let mut turn = 0usize;
    while !stop.load(Ordering::Relaxed) {
        let url = {
            let urls = urls.lock().unwrap();
            urls[turn % urls.len()].clone()
        };
        turn += 1;
        let Some(v) = view(&http, &url).await else {
            tokio::time::sleep(Duration::from_millis(20)).await;
            continue;
        };
        seen += 1;
        if let Some(epoch) = v["lease"]["epoch"].as_i64() {
            assert!(epoch >= highest, "the lease's epoch went back from {highest}: {v}");
            highest = epoch;
        }
        if v["role"] == "active" {
            let (epoch, node) = (v["epoch"].as_i64().expect("an active node's epoch"), v["node"].to_string());
            match terms.iter().find(|(e, _)| *e == epoch) {
                Some((_, other)) => assert_eq!(*other, node, "epoch {epoch} reported active by two nodes"),
                None => terms.push((epoch, node)),
            }
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    seen
}
