//! Who may read and write tags once API keys are configured: viewers read, operators write.

use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::store::Engine;
use serde_json::json;

use super::*;
use crate::support::eventually;
use crate::support::{assert_error, spawn_with, split};

fn key(name: &str, role: Role) -> KeyConfig {
    KeyConfig { name: name.into(), role, hash: KeyHash::of(&format!("key-{name}")) }
}

#[tokio::test]
async fn viewers_read_tags_and_operators_write_them() {
    let (bank, server) = modbus_sim().await;
    let device = tags_device("tags1", "modbus-tcp", &server.local_addr().unwrap().to_string(), MODBUS_TAGS);
    let app = spawn_with(Engine::Sqlite, |c| {
        c.devices = vec![device.into()];
        c.auth.keys = vec![key("v", Role::Viewer), key("o", Role::Operator), key("a", Role::Admin)];
    })
    .await;
    let url = app.url("/api/v1/devices/tags1/tags/beacon.red");
    let post = |k: Option<&str>, on: bool| {
        let mut req = app.client.post(&url).json(&json!({ "value": on }));
        if let Some(k) = k {
            req = req.bearer_auth(k);
        }
        async move { split(req.send().await.unwrap()).await }
    };
    assert_error(&post(None, true).await, 401, "unauthorized");
    assert_error(&post(Some("key-v"), true).await, 403, "forbidden");
    assert!(!bank.lock().coils[5], "a refused caller wrote nothing");
    let list =
        app.client.get(app.url("/api/v1/devices/tags1/tags")).bearer_auth("key-v").send().await.unwrap();
    assert_eq!(list.status(), 200, "viewers read tags");

    // Writes wait for the first poll to bring the device online.
    let got =
        eventually("a write once the device is online", std::time::Duration::from_secs(5), async || {
            let got = post(Some("key-o"), true).await;
            if got.0 == 200 {
                return Ok(got);
            }
            assert_error(&got, 503, "device_offline");
            Err(got)
        })
        .await;
    assert_eq!(got.1["value"], true, "{got:?}");
    assert!(bank.lock().coils[5], "an operator's write lands");
    let got = post(Some("key-a"), false).await;
    assert_eq!(got.0, 200, "admins may do everything: {got:?}");
    assert!(!bank.lock().coils[5]);
}
