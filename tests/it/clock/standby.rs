//! Two nodes of a hot-standby cluster on one PostgreSQL, the wall clock stepped an hour
//! forward: the active node keeps renewing its lease, and the standby does not take over.
//! Both nodes run in this process, so both see the step; neither's lease rules read the
//! wall clock (`rackd::service::cluster`), which is what this shows.

use std::time::Duration;

use rackd::config::{ClusterConfig, Config};
use rackd::domain::time::step_wall_clock;
use rackd::store::Database;
use rackd::store::cluster::{LEASE, read};
use serde_json::json;
use sqlx::PgPool;

use super::{HOUR, alone};
use crate::support::{TestApp, eventually, spawn_on};

const LEASE_MS: u64 = 1500;

async fn node(db: &str, name: &str, site: &Config) -> TestApp {
    let (name, devices) = (name.to_owned(), site.devices.clone());
    spawn_on(Database::Postgres(db.to_owned()), move |c| {
        c.devices = devices;
        c.cluster =
            Some(ClusterConfig { node: name, lease_ms: LEASE_MS, margin_ms: None, url: None, ca_file: None });
    })
    .await
}

#[test]
fn a_step_forward_takes_no_lease() {
    alone("clock::standby::a_step_forward_takes_no_lease", async || {
        let db = crate::support::postgres::database().await;
        let mut site = Config::demo();
        let _sims = rackd::cli::demo::start_with(&mut site, crate::api::demo::FAST).await.unwrap();
        let a = node(&db, "a", &site).await;
        eventually("node a to be active", Duration::from_secs(10), async || {
            let (_, c) = a.get("/api/v1/cluster").await;
            if c["role"] == "active" { Ok(()) } else { Err(c) }
        })
        .await;
        let b = node(&db, "b", &site).await;
        let pool = PgPool::connect(&db).await.unwrap();
        let before = read(&pool, LEASE).await.unwrap().expect("the lease is held");

        for step in [HOUR, -HOUR, HOUR] {
            let at = read(&pool, LEASE).await.unwrap().unwrap();
            step_wall_clock(step);
            // Eight renewals, one every lease / 3: over twice the 1.2 leases (lease +
            // margin) a standby waits before it takes a still lease. Had the step let b take
            // over, or made a stop renewing, it would have happened by now.
            let renewals = 8;
            let now = eventually("the lease renewed through the step", Duration::from_secs(30), async || {
                let row = read(&pool, LEASE).await.unwrap().unwrap();
                if row.epoch != at.epoch || row.beat >= at.beat + renewals { Ok(row) } else { Err(row) }
            })
            .await;
            assert_eq!((now.holder.as_str(), now.epoch), ("a", before.epoch), "the lease moved: {now:?}");
        }
        assert_eq!(b.get("/readyz").await, (200, json!({"status": "ok", "role": "standby"})));
        assert_eq!(a.get("/readyz").await, (200, json!({"status": "ok", "role": "active"})));
        let (_, alarms) = a.get("/api/v1/alarms?limit=100").await;
        assert!(
            !alarms["alarms"].as_array().unwrap().iter().any(|x| x["kind"] == "takeover"),
            "no takeover alarm: {alarms}"
        );
        pool.close().await;
        b.stop().await;
        a.stop().await;
    });
}
