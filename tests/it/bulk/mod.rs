//! Operators' bulk actions over the real server on both engines: unlock by cause, retry
//! failed jobs, cancel queued ones; all or nothing, with a dry run, audited. The shelf
//! simulator supplies the failures: a power cycle that makes it lose its memory, retrieves
//! from empty locations that it rejects.

mod actions;
mod memory_loss;

use rackd::sim::shelf::ShelfSim;
use rackd::store::Engine;
use serde_json::Value;

use crate::shelf::{device_for, sim};
use crate::support::{TestApp, eventually, spawn_with};

/// A shelf simulator whose tasks take `ms` milliseconds, and a rackd on `engine` driving
/// it as `shelf1`, serving `aisles`.
async fn shelf_on(engine: Engine, ms: u64, aisles: &[u16]) -> (TestApp, ShelfSim) {
    let sim = ShelfSim::start("127.0.0.1:0", sim(ms)).await.unwrap();
    let device = device_for(&sim, |d| d.aisles = aisles.to_vec());
    let app = spawn_with(engine, |c| c.devices = vec![device.into()]).await;
    (app, sim)
}

/// The job as it stands.
async fn job(app: &TestApp, id: i64) -> Value {
    app.get(&format!("/api/v1/jobs/{id}")).await.1
}

/// Waits (at most `secs`) until every one of `ids` passes `check`.
async fn wait_jobs(app: &TestApp, ids: &[i64], secs: u64, what: &str, check: impl Fn(&Value) -> bool) {
    eventually(what, std::time::Duration::from_secs(secs), async || {
        for id in ids {
            let j = job(app, *id).await;
            if !check(&j) {
                return Err(j);
            }
        }
        Ok(())
    })
    .await
}

/// The audit log's newest `n` entries as (action, target, reason).
async fn audit(app: &TestApp, n: usize) -> Vec<(String, String, String)> {
    let (_, page) = app.get(&format!("/api/v1/audit?limit={n}")).await;
    page["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            let text = |k: &str| e[k].as_str().unwrap_or_default().to_owned();
            (text("action"), text("target"), text("reason"))
        })
        .collect()
}

/// Now, as RFC 3339.
fn now() -> String {
    time::OffsetDateTime::now_utc().format(&time::format_description::well_known::Rfc3339).unwrap()
}
