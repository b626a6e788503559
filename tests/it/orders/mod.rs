//! Orders end to end (issue 52): sequences, deadlines and dependencies, over the real crane
//! simulators, and the API's refusals on both engines.

mod deadline;
mod dependency;
mod refusals;
mod sequence;

use rackd::config::devices::CraneConfig;
use rackd::config::{AisleConfig, Config, StationConfig, Transit};
use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::CraneSim;
use rackd::store::Engine;
use serde_json::{Value, json};

use crate::crane::{crane, device_for};
use crate::support::{TestApp, spawn_with};

/// Two crane aisles, 2 and 3, each with its crane (`crane1`, `crane2`), and station 1 with
/// these transits from aisles 2 and 3 (seconds).
pub async fn two_cranes(engine: Engine, transit: (f64, f64)) -> (TestApp, CraneSim, CraneSim) {
    let (sim2, sim3) = (crane(TransportKind::Tcp, 5).await, crane(TransportKind::Tcp, 5).await);
    let one: CraneConfig = device_for(&sim2, TransportKind::Tcp, |_| {});
    let two: CraneConfig = device_for(&sim3, TransportKind::Tcp, |d| {
        d.id = "crane2".into();
        d.aisles = vec![3];
    });
    let app = spawn_with(engine, |c: &mut Config| {
        c.site.aisles.retain(|a| a.aisle == 1);
        for aisle in [2, 3] {
            c.site.aisles.push(AisleConfig { aisle, rows: 2, bays: 20, levels: 8, positions: 2, depth: 1 });
        }
        c.site.stations = vec![StationConfig {
            id: 1,
            name: Some("pick 1".into()),
            transit: vec![Transit { aisle: 2, seconds: transit.0 }, Transit { aisle: 3, seconds: transit.1 }],
        }];
        c.devices = vec![one.into(), two.into()];
    })
    .await;
    (app, sim2, sim3)
}

/// A location in crane aisle `aisle`.
pub fn at(aisle: u16, bay: u16, level: u16) -> Value {
    json!({"aisle": aisle, "row": 1, "bay": bay, "level": level, "position": 1})
}

/// When job `id` entered `state` (the last time), in Unix ms, from its history.
pub async fn entered(app: &TestApp, id: i64, state: &str) -> Option<i64> {
    let (_, h) = app.get(&format!("/api/v1/jobs/{id}/history")).await;
    let at = h.as_array()?.iter().rev().find(|e| e["state"] == state)?["at"].as_str()?.to_owned();
    let t = time::OffsetDateTime::parse(&at, &time::format_description::well_known::Rfc3339).ok()?;
    Some((t.unix_timestamp_nanos() / 1_000_000) as i64)
}
