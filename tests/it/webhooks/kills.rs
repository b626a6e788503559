//! Delivery through crashes, on SQLite: a `rackd serve` process drives a simulated shelf
//! PLC and a simulated crane (they run in this test process and outlive it) and delivers
//! `job.*` events to a receiver that fails 30% of calls, answers some too late, and goes
//! down for a few seconds; the process is SIGKILLed twice while jobs run and deliveries are
//! under way, and started again each time.
//!
//! It proves that delivery loses nothing and changes nothing on the job path: every `job.*`
//! event reaches the receiver with a 2xx at least once, first arrivals in `seq` order, every
//! signature valid, a duplicate only with the same `webhook-id` and body; the stored cursor,
//! sampled all along, never passes an event the receiver did not acknowledge; the `webhook`
//! alarm is raised while the receiver is down and cleared after; every job completes once,
//! no task reaches a machine twice, and neither simulator sees a breach of its interface.
//! The same on PostgreSQL with two nodes is `standby::failover`.

use std::time::Duration;

use rackd::cli::demo;
use rackd::config::Config;
use rackd::config::devices::CraneConfig;
use rackd::sim::crane::{CraneSim, CraneSimOptions};
use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};
use serde_json::{Value, json};
use sqlx::SqlitePool;

use super::api::subscription;
use crate::support::eventually;
use crate::support::node::Node;
use crate::support::receiver::{Mode, Receiver};

/// Jobs posted in all.
const JOBS: usize = 200;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deliveries_survive_sigkills_and_a_receiver_that_fails_and_goes_down() {
    let shelf = ShelfSimOptions { task_time: Duration::from_millis(100), slots: 8, ..Default::default() };
    let shelf = ShelfSim::start("127.0.0.1:0", shelf).await.unwrap();
    let crane = CraneSimOptions { step: Duration::from_millis(20), ..Default::default() };
    let crane = CraneSim::start("127.0.0.1:0", crane).await.unwrap();
    let mut receiver = Receiver::start().await;
    let chaos = Mode { fail: 0.3, late_share: 0.02, late: Duration::from_millis(400), ..Mode::default() };
    receiver.set(chaos.clone());
    let dir = tempfile::tempdir().unwrap();
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    config.database.path = dir.path().join("rackd.db");
    let mut shelf1 = demo::shelf_device(&shelf, "shelf1", &shelf.local_addr().unwrap().to_string(), vec![1]);
    shelf1.poll_ms = 50;
    let mut crane1 = CraneConfig::new("crane1", &crane.local_addr().to_string(), vec![2]);
    crane1.poll_ms = 50;
    config.devices = vec![shelf1.into(), crane1.into()];
    let mut webhook = subscription(&receiver);
    webhook.timeout_ms = 200;
    config.webhooks = vec![webhook];
    let mut node = Node::new(dir.path(), "rackd", &config);
    node.start();
    let http = reqwest::Client::builder().timeout(Duration::from_secs(5)).build().unwrap();
    let health = format!("{}/healthz", node.url);
    eventually("rackd to answer", Duration::from_secs(30), async || {
        http.get(&health).send().await?.error_for_status()
    })
    .await;
    let db =
        SqlitePool::connect(&format!("sqlite:{}?mode=ro", config.database.path.display())).await.unwrap();
    let mut posted = Vec::new();
    for n in 0..JOBS {
        posted.push(post(&http, &node.url, n).await);
        cursor_is_acknowledged(&db, &receiver).await;
        if n == 60 || n == 140 {
            node.kill();
            node.start();
        }
        if n == 100 {
            receiver.down();
        }
        if n == 110 {
            // Down for longer than the alarm's second: wait for the alarm before coming back.
            eventually("the webhook alarm", Duration::from_secs(15), async || {
                webhook_alarms(&http, &node.url, true).await
            })
            .await;
            receiver.up().await;
            receiver.set(chaos.clone());
        }
        tokio::time::sleep(Duration::from_millis(15)).await;
    }
    eventually("every job to end", Duration::from_secs(90), async || {
        let open: i64 = sqlx::query_scalar(
            "SELECT COUNT(*) FROM jobs WHERE state NOT IN ('completed', 'failed', 'cancelled')",
        )
        .fetch_one(&db)
        .await
        .unwrap();
        if open == 0 { Ok(()) } else { Err(open) }
    })
    .await;
    let wanted: Vec<i64> = sqlx::query_scalar("SELECT seq FROM events WHERE type LIKE 'job.%' ORDER BY seq")
        .fetch_all(&db)
        .await
        .unwrap();
    super::every_event_acked(&receiver, &wanted).await;
    cursor_is_acknowledged(&db, &receiver).await;
    receiver.check("wms", "job.");
    eventually("the webhook alarm to clear", Duration::from_secs(15), async || {
        webhook_alarms(&http, &node.url, false).await
    })
    .await;
    assert!(node.running(), "rackd exited");

    let jobs: Vec<(i64, String)> =
        sqlx::query_as("SELECT id, state FROM jobs ORDER BY id").fetch_all(&db).await.unwrap();
    assert_eq!(jobs.len(), JOBS, "only the posted jobs exist");
    let not_completed: Vec<_> = jobs.iter().filter(|(_, state)| state != "completed").collect();
    assert!(not_completed.is_empty(), "jobs that did not complete: {not_completed:?}");
    crate::support::machines::each_task_once_and_no_breach(&shelf, &crane, &posted);
    let received = receiver.received();
    let failed = received.iter().filter(|r| r.status >= 300 || r.late).count();
    eprintln!(
        "webhooks through 2 SIGKILLs: {} job events, {} requests ({failed} failed or late), {} jobs",
        wanted.len(),
        received.len(),
        jobs.len()
    );
}

/// Job `n`: three in four on the shelf (a store to a place of its own), one in four on the
/// crane (a store to a near place of its own, or an empty travel). Its id and aisle.
async fn post(http: &reqwest::Client, url: &str, n: usize) -> (i64, u16) {
    let (aisle, mut job) = if n % 4 == 3 {
        let k = n / 4;
        let job = match k % 2 {
            0 => {
                let to = json!({"aisle": 2, "row": 1 + k / 2 % 2, "bay": 1 + k / 4 % 20, "level": 1 + k / 80 % 7, "position": 1});
                json!({"kind": "store", "barcode": format!("C-{n}"), "to": to})
            }
            _ => {
                json!({"kind": "travel", "to": {"aisle": 2, "row": 1, "bay": 1 + k % 20, "level": 8, "position": 1}})
            }
        };
        (2, job)
    } else {
        let to = json!({"aisle": 1, "row": 1 + n % 2, "bay": 1 + n / 2 % 10, "level": 1 + n / 20 % 6, "position": 1 + n / 120 % 4});
        (1, json!({"kind": "store", "barcode": format!("S-{n}"), "to": to}))
    };
    job["reference"] = json!(format!("kills-{n}"));
    // While rackd restarts the post is tried again; the reference makes a second try of a
    // job already taken answer that job.
    eventually("rackd to take a job", Duration::from_secs(30), async || {
        let answer =
            http.post(format!("{url}/api/v1/jobs")).json(&job).send().await.map_err(|e| e.to_string())?;
        let status = answer.status().as_u16();
        let body: Value = answer.json().await.unwrap_or_default();
        assert!(!(400..500).contains(&status), "refused {job}: {status} {body}");
        body["id"].as_i64().map(|id| (id, aisle)).ok_or(format!("{status} {body}"))
    })
    .await
}

/// The stored cursor passes no `job.*` event the receiver has not acknowledged.
async fn cursor_is_acknowledged(db: &SqlitePool, receiver: &Receiver) {
    let Ok(Some(cursor)) = sqlx::query_scalar::<_, i64>("SELECT cursor FROM webhooks WHERE name = 'wms'")
        .fetch_optional(db)
        .await
    else {
        return;
    };
    let passed: Vec<i64> = sqlx::query_scalar("SELECT seq FROM events WHERE type LIKE 'job.%' AND seq <= $1")
        .bind(cursor)
        .fetch_all(db)
        .await
        .unwrap();
    super::assert_cursor_acknowledged(cursor, &passed, receiver);
}

/// Ok when the active `webhook` alarms are (`raised`) or are not there.
async fn webhook_alarms(http: &reqwest::Client, url: &str, raised: bool) -> Result<(), String> {
    let page: Value = http
        .get(format!("{url}/api/v1/alarms?active=true"))
        .send()
        .await
        .map_err(|e| e.to_string())?
        .json()
        .await
        .map_err(|e| e.to_string())?;
    let n = page["alarms"].as_array().map_or(0, |a| a.iter().filter(|a| a["kind"] == "webhook").count());
    if (n > 0) == raised { Ok(()) } else { Err(format!("{n} webhook alarms")) }
}
