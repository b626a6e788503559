//! Tag I/O end to end: the real server on 127.0.0.1:0 with a temporary database, polling
//! and writing tags of real simulators over real sockets (Modbus TCP, PPI and MEWTOCOL over
//! TCP).

use rackd::store::Engine;
mod access;
mod errors;
mod events;
mod lines;
mod modbus;

use std::sync::Arc;
use std::time::Duration;

use rackd::config::devices::{DeviceConfig, TagsConfig};
use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerHandle, ServerOptions};
use serde_json::{Value, json};

use crate::support::eventually;
use crate::support::held::HeldPort;
use crate::support::{TestApp, spawn_with};

/// A tags device entry: fast polling, short timeouts, offline after two failed requests.
pub fn tags_device(id: &str, protocol: &str, address: &str, tags: &str) -> TagsConfig {
    let text = format!(
        "id = {id:?}\nkind = \"tags\"\nprotocol = {protocol:?}\naddress = {address:?}\npoll_ms = 20\n\
         timeout_ms = 250\nretries = 2\noffline_after = 2\n[tags]\n{tags}"
    );
    let device: DeviceConfig = toml::from_str(&text).unwrap();
    device.check().unwrap();
    match device {
        DeviceConfig::Tags(tags) => tags,
        other => panic!("not a tags device: {other:?}"),
    }
}

/// A Modbus TCP register bank on a free port.
pub async fn modbus_sim() -> (Bank, ServerHandle) {
    modbus_sim_at("127.0.0.1:0").await
}

/// A Modbus TCP register bank on `address`.
async fn modbus_sim_at(address: &str) -> (Bank, ServerHandle) {
    let bank = Bank::new();
    let server = ModbusServer::new(Arc::new(bank.clone()), ServerOptions::default());
    (bank.clone(), server.serve_tcp(address).await.unwrap())
}

/// A Modbus TCP register bank on a port the test holds (to start it again there).
pub fn modbus_sim_on(port: &HeldPort) -> (Bank, ServerHandle) {
    let bank = Bank::new();
    let server = ModbusServer::new(Arc::new(bank.clone()), ServerOptions::default());
    (bank.clone(), server.serve_tcp_on(port.listen()).unwrap())
}

/// The tags of the Modbus tests: every type, both word orders, bits of words, coils,
/// inputs, limits and a read-only word.
pub const MODBUS_TAGS: &str = r#"
"plain.u16" = "4x10"
"plain.i16" = { address = "4x11", type = "i16" }
"plain.u32" = { address = "4x12", type = "u32" }
"plain.f32_low" = { address = "4x14", type = "f32", word_order = "low-first" }
"plain.i32" = { address = "4x20", type = "i32" }
"plain.f32" = { address = "4x22", type = "f32", min = -10, max = 10.5 }
"plain.limited" = { address = "4x24", min = 10, max = 20 }
"plain.fixed" = { address = "4x25", writable = false }
"word.bit3" = "4x16.3"
"beacon.red" = "0x5"
"station1.box_present" = "1x7"
"analog.level" = { address = "3x2", type = "i16" }
"#;

/// A Modbus TCP simulator and a rackd with one tags device `tags1` on it.
pub async fn modbus_app() -> (TestApp, Bank, ServerHandle) {
    modbus_app_with(modbus_sim().await).await
}

/// A rackd with one tags device `tags1` on the Modbus TCP simulator `sim`.
pub async fn modbus_app_with((bank, server): (Bank, ServerHandle)) -> (TestApp, Bank, ServerHandle) {
    let device = tags_device("tags1", "modbus-tcp", &server.local_addr().unwrap().to_string(), MODBUS_TAGS);
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.into()]).await;
    (app, bank, server)
}

/// One tag of a device as the API lists it.
pub async fn tag(app: &TestApp, device: &str, name: &str) -> Value {
    let (status, tags) = app.get(&format!("/api/v1/devices/{device}/tags")).await;
    assert_eq!(status, 200, "{tags}");
    let found = tags.as_array().unwrap().iter().find(|t| t["name"] == name).cloned();
    found.unwrap_or_else(|| panic!("no tag {name} in {tags}"))
}

/// Waits (bounded) until tag `name` satisfies `pred`; returns it.
pub async fn wait_tag(app: &TestApp, device: &str, name: &str, pred: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("tag {name} to get there"), Duration::from_secs(5), async || {
        let t = tag(app, device, name).await;
        if pred(&t) { Ok(t) } else { Err(t) }
    })
    .await
}

/// Waits (bounded) until the device status satisfies `pred`; returns it.
pub async fn wait_device(app: &TestApp, device: &str, pred: impl Fn(&Value) -> bool) -> Value {
    eventually(format!("device {device} to get there"), Duration::from_secs(5), async || {
        let (_, status) = app.get(&format!("/api/v1/devices/{device}")).await;
        if pred(&status) { Ok(status) } else { Err(status) }
    })
    .await
}

/// Writes a tag through the API.
pub async fn write(app: &TestApp, device: &str, name: &str, value: Value) -> (u16, Value) {
    app.post(&format!("/api/v1/devices/{device}/tags/{name}"), &json!({ "value": value })).await
}
