//! Every change made through the API is in the audit log with the key's name and the
//! client's address: submissions (one entry per request; a batch's names its count; a
//! repeated submission that changed nothing has none), a new priority, a cancel, pauses,
//! locks, the inventory, an alarm acknowledgement and a tag write. Before issue 41 the first
//! four left no entry at all, and no entry named an address. On both engines (the address
//! is a column of its own, added by a migration on each).

use std::net::{IpAddr, Ipv4Addr};
use std::time::Duration;

use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use crate::support::{TestApp, eventually, loc, spawn_with, split};
use crate::tags::{MODBUS_TAGS, modbus_sim, tags_device};

const OPERATOR: &str = "rk_security-audit-operator";
const ADMIN: &str = "rk_security-audit-admin";

/// A client whose requests come from `127.0.0.N`.
fn from(n: u8) -> reqwest::Client {
    reqwest::Client::builder().local_address(IpAddr::V4(Ipv4Addr::new(127, 0, 0, n))).build().unwrap()
}

async fn call(
    app: &TestApp,
    client: &reqwest::Client,
    key: &str,
    method: &str,
    path: &str,
    body: Value,
) -> (u16, Value) {
    let request = client.request(method.parse().unwrap(), app.url(path)).bearer_auth(key).json(&body);
    split(request.send().await.unwrap()).await
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_change_is_audited_with_the_key_and_the_address(#[case] engine: Engine) {
    let (_bank, server) = modbus_sim().await;
    let tags = tags_device("tags1", "modbus-tcp", &server.local_addr().unwrap().to_string(), MODBUS_TAGS);
    // Nothing listens on port 1: this one goes offline at once, with a link alarm.
    let dead = tags_device("tags2", "modbus-tcp", "127.0.0.1:1", "\"x\" = \"0x1\"\n");
    let app = spawn_with(engine, |c| {
        c.devices.push(tags.into());
        c.devices.push(dead.into());
        c.auth.keys = vec![
            KeyConfig { name: "wms".into(), role: Role::Operator, hash: KeyHash::of(OPERATOR) },
            KeyConfig { name: "maintenance".into(), role: Role::Admin, hash: KeyHash::of(ADMIN) },
        ];
    })
    .await;
    let (wms, desk) = (from(7), from(8));
    let op = |method: &'static str, path: String, body: Value| {
        let (app, wms) = (&app, &wms);
        async move { call(app, wms, OPERATOR, method, &path, body).await }
    };

    let job = json!({"kind": "store", "reference": "AUD-1", "barcode": "B1", "to": loc(1, 2, 3, 1)});
    let (status, one) = op("POST", "/api/v1/jobs".into(), job.clone()).await;
    assert_eq!(status, 201, "{one}");
    let (status, _) = op("POST", "/api/v1/jobs".into(), job).await;
    assert_eq!(status, 200, "the same submission again changes nothing");
    let lights: Vec<Value> = (1..=3u16)
        .map(|b| json!({"kind": "light", "location": loc(1, b, 1, 1), "color": "green", "on": true}))
        .collect();
    let (status, batch) = op("POST", "/api/v1/jobs/batch".into(), json!({"jobs": lights})).await;
    assert_eq!(status, 201, "{batch}");
    let id = one["id"].as_i64().unwrap();
    let first = batch["jobs"][0]["id"].as_i64().unwrap();
    let (status, _) = op("PATCH", format!("/api/v1/jobs/{id}"), json!({"priority": 3})).await;
    assert_eq!(status, 200);
    let (status, cancelled) = op("POST", format!("/api/v1/jobs/{first}/cancel"), json!({})).await;
    assert_eq!(status, 200, "{cancelled}");
    for action in ["pause", "resume"] {
        let (status, _) = op("POST", format!("/api/v1/aisles/1/{action}"), json!({})).await;
        assert_eq!(status, 200);
    }
    let (status, _) = op("POST", "/api/v1/locations/1/1/1/1/1/lock".into(), json!({"reason": "check"})).await;
    assert_eq!(status, 200);
    let (status, _) = op("POST", "/api/v1/locations/1/1/1/1/1/unlock".into(), json!({})).await;
    assert_eq!(status, 200);
    let stock =
        json!({"locations": [{"aisle": 1, "row": 1, "bay": 9, "level": 1, "position": 1, "occupied": true}]});
    let (status, _) = call(&app, &desk, ADMIN, "PUT", "/api/v1/locations", stock).await;
    assert_eq!(status, 200);
    let wrote = eventually("a tag write once tags1 is online", Duration::from_secs(10), async || {
        let got = op("POST", "/api/v1/devices/tags1/tags/beacon.red".into(), json!({"value": true})).await;
        if got.0 == 200 { Ok(got) } else { Err(got) }
    })
    .await;
    assert_eq!(wrote.1["value"], true);
    let alarm = eventually("tags2's link alarm", Duration::from_secs(10), async || {
        let (_, page) = op("GET", "/api/v1/alarms?active=true".into(), Value::Null).await;
        page["alarms"].as_array().unwrap().iter().find(|a| a["device"] == "tags2").cloned().ok_or(page)
    })
    .await;
    let (status, _) = op("POST", format!("/api/v1/alarms/{}/acknowledge", alarm["id"]), json!({})).await;
    assert_eq!(status, 200);

    let (status, page) = op("GET", "/api/v1/audit?limit=1000".into(), Value::Null).await;
    assert_eq!(status, 200, "{page}");
    let mut entries: Vec<Value> = page["entries"].as_array().unwrap().clone();
    entries.reverse();
    let seen: Vec<(String, String, String, String)> = entries
        .iter()
        .map(|e| {
            let s = |k: &str| e[k].as_str().unwrap_or("-").to_owned();
            (s("action"), s("target"), s("by"), s("client"))
        })
        .collect();
    let wms_at =
        |action: &str, target: String| (action.to_owned(), target, "wms".to_owned(), "127.0.0.7".to_owned());
    let last = batch["jobs"][2]["id"].as_i64().unwrap();
    let expected = vec![
        wms_at("submit", format!("job:{id}")),
        wms_at("submit", format!("jobs:{first}-{last}")),
        wms_at("priority", format!("job:{id}")),
        wms_at("cancel", format!("job:{first}")),
        wms_at("pause", "aisle:1".into()),
        wms_at("resume", "aisle:1".into()),
        wms_at("lock", "location:1/1/1/1/1".into()),
        wms_at("unlock", "location:1/1/1/1/1".into()),
        ("inventory".into(), "location:1/1/9/1/1".into(), "maintenance".into(), "127.0.0.8".into()),
        wms_at("tag", "device:tags1/beacon.red".into()),
        wms_at("acknowledge", format!("alarm:{}", alarm["id"])),
    ];
    assert_eq!(seen, expected, "{entries:#?}");
    let reason = |i: usize| entries[i]["reason"].clone();
    assert_eq!(reason(1), json!("a batch of 3 jobs"));
    assert_eq!(reason(2), json!("priority 10 -> 3"));
    assert_eq!(reason(9), json!("value true"));
    app.stop().await;
}
