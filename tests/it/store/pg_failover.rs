//! PostgreSQL failing over to a promoted replica, three times, under rackd at work (issue
//! 53): a primary and a streaming replica of the test's own (`support::pg_owned`), the
//! replica synchronous (a commit is acknowledged once the replica has it), and rackd's
//! `database.url` listing both hosts with `target_session_attrs=read-write`
//! (`store::hosts`). While a WMS posts jobs (`support::flow`) and the demo site's shelf and
//! crane simulators run them, each round stops the primary at once (`-m immediate`),
//! waits until `GET /api/v1/health` tells why, promotes the replica, and times "back to
//! work": from the promotion done (the new primary takes writes) to the first job rackd
//! accepts after it. The old primary is then rebuilt as the new one's replica (a base
//! backup) and made synchronous, for the next round.
//!
//! At the end, as after the restarts (`store::pg_restart`): every job accepted with a 2xx
//! is in the store once, under the id it was answered with; every job completed once;
//! each task reached its machine once; no busy-slot write, no breach of the crane's
//! hand-over; `store` alarms raised and cleared.

use std::time::{Duration, Instant};

use rackd::cli::demo::{self, Pace};
use rackd::config::Config;
use rackd::store::Database;
use sqlx::PgPool;

use super::pg_restart::{Figure, health_tells_down, nothing_lost_nor_twice};
use crate::api::waiting::wait_for_online;
use crate::support::flow::Flow;
use crate::support::pg_owned::Owned;
use crate::support::{eventually, spawn_on};

const FAILOVERS: usize = 3;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_failovers_to_a_promoted_replica_lose_nothing_and_run_nothing_twice() {
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
    let app = spawn_on(Database::Postgres(url.clone()), |c| {
        c.site = site.site.clone();
        c.devices = site.devices.clone();
    })
    .await;
    wait_for_online(&app, "shelf1").await;
    wait_for_online(&app, "crane1").await;
    let flow = Flow::start(vec![app.base.clone()], Duration::from_millis(150), "failover");

    let mut primary = 0;
    let mut figures = Vec::new();
    for round in 1..=FAILOVERS {
        let from = flow.count();
        eventually("three more jobs accepted", Duration::from_secs(20), async || {
            if flow.count() >= from + 3 { Ok(()) } else { Err(flow.count()) }
        })
        .await;
        let (old, new) = pair(&mut servers, primary);
        old.crash().await;
        let crashed = Instant::now();
        let told = health_tells_down(&app, crashed).await;
        new.promote().await;
        let up = Instant::now();
        let back = eventually("a job accepted after the promotion", Duration::from_secs(10), async || {
            flow.first_after(up).ok_or("none yet")
        })
        .await;
        let figure = Figure { told, down: up - crashed, back: back.at - up };
        eprintln!("failover {round}: {figure:?}");
        figures.push(figure);
        // The old primary, rebuilt as the new one's replica, synchronous for the next round.
        old.rebuild_from(new).await;
        new.synchronous().await;
        assert!(old.in_recovery().await && !new.in_recovery().await);
        primary = 1 - primary;
    }
    let accepted = flow.stop().await;

    let db = PgPool::connect(&servers[primary].url("rackd")).await.unwrap();
    nothing_lost_nor_twice(&db, &accepted, (&shelf, &crane), &app, &figures).await;
    app.stop().await;
}

/// The server at `primary` and the other.
fn pair(servers: &mut [Owned; 2], primary: usize) -> (&mut Owned, &mut Owned) {
    let [a, b] = servers;
    if primary == 0 { (a, b) } else { (b, a) }
}
