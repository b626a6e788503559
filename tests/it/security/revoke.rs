//! Issue 51, item 2: keys are revoked without a restart. `[auth]` is reloaded (by SIGHUP or
//! `POST /api/v1/config/reload`): a key removed from the file is refused from the next
//! request on, its WebSockets are closed, a key added works, the failed-key limit is the
//! new one, and the audit names the keys, never a key or its hash. A reload that would
//! leave no key (keyless mode) is refused. A SIGHUP whose file is refused raises the
//! `config_reload` alarm until a reload is applied. Before the fix `[auth]` was fixed at
//! run time: every such reload was refused (409 `fixed_key`), a refused SIGHUP only logged.

use std::time::{Duration, Instant};

use rackd::auth::{KeyConfig, KeyHash, Role};
use rackd::config::Config;
use serde_json::{Value, json};

use crate::support::node::Node;
use crate::support::ws::{Got, Ws};
use crate::support::{assert_error, eventually, spawn_from_file, split};

const ADMIN: &str = "rk_revoke-admin-0123456789";
const WMS: &str = "rk_revoke-wms-0123456789";
const WMS_2: &str = "rk_revoke-wms2-0123456789";

/// One aisle and one shelf where nothing answers, with `keys`.
fn site(keys: &[(&str, Role, &str)]) -> String {
    let mut text = String::new();
    for (name, role, key) in keys {
        let (role, hash) = (role.as_str(), KeyHash::of(key));
        text += &format!("[[auth.keys]]\nname = \"{name}\"\nrole = \"{role}\"\nhash = \"{hash}\"\n\n");
    }
    text + "[[site.aisles]]\naisle = 1\nrows = 1\nbays = 2\nlevels = 1\npositions = 1\n\n\
             [[devices]]\nid = \"shelf-1\"\nkind = \"shelf\"\naddress = \"127.0.0.1:9\"\naisles = [1]\n"
}

fn key(name: &str, role: Role, key: &str) -> KeyConfig {
    KeyConfig { name: name.into(), role, hash: KeyHash::of(key) }
}

async fn get(http: &reqwest::Client, base: &str, path: &str, key: &str) -> (u16, Value) {
    split(http.get(format!("{base}{path}")).bearer_auth(key).send().await.unwrap()).await
}

/// The active `config_reload` alarms.
async fn reload_alarms(http: &reqwest::Client, base: &str) -> Vec<Value> {
    let (status, body) = get(http, base, "/api/v1/alarms?active=true", ADMIN).await;
    assert_eq!(status, 200, "{body}");
    let alarms = body["alarms"].as_array().unwrap().iter();
    alarms.filter(|a| a["kind"] == "config_reload").cloned().collect()
}

/// The done-when of the issue, on a `rackd serve --config` process: the key removed from
/// the file and SIGHUP, the key gets 401 within a second; a refused SIGHUP is an alarm
/// until a reload is applied.
#[tokio::test]
async fn a_key_removed_from_the_file_is_refused_within_a_second_of_a_sighup() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("rackd.toml");
    let keys = [("admin", Role::Admin, ADMIN), ("wms", Role::Operator, WMS)];
    let mut config = Config::parse(&site(&keys), &file).unwrap();
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    config.database.path = dir.path().join("rackd.db");
    let mut node = Node::new(dir.path(), "rackd", &config);
    node.start();
    let (http, base) = (reqwest::Client::new(), node.url.clone());
    eventually("rackd to answer", Duration::from_secs(30), async || {
        http.get(format!("{base}/healthz")).send().await?.error_for_status()
    })
    .await;
    assert_eq!(get(&http, &base, "/api/v1/whoami", WMS).await.0, 200);

    // The key removed (and another added beside it), then SIGHUP.
    config.auth.keys = vec![key("admin", Role::Admin, ADMIN), key("wms-2", Role::Operator, WMS_2)];
    std::fs::write(node.config_file(), toml::to_string(&config).unwrap()).unwrap();
    let sent = Instant::now();
    node.hang_up();
    eventually("the removed key to be refused", Duration::from_secs(10), async || {
        let got = get(&http, &base, "/api/v1/whoami", WMS).await;
        if got.0 == 401 { Ok(got) } else { Err(got) }
    })
    .await;
    let took = sent.elapsed();
    assert!(took < Duration::from_secs(1), "the key was refused {took:?} after the SIGHUP");
    assert_error(&get(&http, &base, "/api/v1/jobs", WMS).await, 401, "unauthorized");
    let (status, who) = get(&http, &base, "/api/v1/whoami", WMS_2).await;
    assert_eq!((status, who), (200, json!({"name": "wms-2", "role": "operator"})));

    // Audited by name, as rackd's own SIGHUP; never a key or its hash, nor in the log.
    let (_, audit) = get(&http, &base, "/api/v1/audit", ADMIN).await;
    let entry = audit["entries"].as_array().unwrap().iter().find(|e| e["action"] == "reload");
    let reason = entry.and_then(|e| e["reason"].as_str()).unwrap_or_default();
    assert!(reason.contains("key wms removed") && reason.contains("key wms-2 added"), "{audit}");
    assert_eq!(entry.map(|e| &e["by"]), Some(&json!("rackd")), "{audit}");
    let hex = |key: &str| KeyHash::of(key).to_string().trim_start_matches("sha256:").to_owned();
    for secret in [WMS, WMS_2, &hex(WMS), &hex(WMS_2)] {
        assert!(!audit.to_string().contains(secret), "the audit holds {secret}: {audit}");
        assert!(!node.log().contains(secret), "the log holds {secret}");
    }

    // A SIGHUP refused: the alarm, with check-config's words; none before.
    assert_eq!(reload_alarms(&http, &base).await, Vec::<Value>::new());
    config.events.buffer += 1;
    std::fs::write(node.config_file(), toml::to_string(&config).unwrap()).unwrap();
    node.hang_up();
    let alarm = eventually("the config_reload alarm", Duration::from_secs(10), async || {
        reload_alarms(&http, &base).await.pop()
    })
    .await;
    assert_eq!((&alarm["device"], &alarm["class"]), (&json!("config"), &json!("link")), "{alarm}");
    let detail = alarm["detail"].as_str().unwrap_or_default();
    assert!(detail.contains("events.buffer") && detail.contains("nothing was applied"), "{alarm}");
    assert!(alarm["action"].as_str().is_some_and(|a| a.contains("check-config")), "{alarm}");

    // The file put right and SIGHUP again: applied, the alarm cleared.
    config.events.buffer -= 1;
    std::fs::write(node.config_file(), toml::to_string(&config).unwrap()).unwrap();
    node.hang_up();
    eventually("the config_reload alarm to clear", Duration::from_secs(10), async || {
        reload_alarms(&http, &base).await.is_empty()
    })
    .await;
    assert!(node.running());
}

async fn reload(http: &reqwest::Client, base: &str, query: &str) -> (u16, Value) {
    let post = http.post(format!("{base}/api/v1/config/reload{query}")).bearer_auth(ADMIN);
    split(post.header("content-type", "application/json").send().await.unwrap()).await
}

/// The API's reload of `[auth]`: what it says, what it applies (the WebSocket of a removed
/// key closed, the new failed-key limit), and the keyless refusal.
#[tokio::test]
async fn a_reload_revokes_a_key_closes_its_sockets_and_sets_the_failed_key_limit() {
    let keys = [("admin", Role::Admin, ADMIN), ("wms", Role::Operator, WMS)];
    let (app, file) = spawn_from_file(&site(&keys)).await;
    let (http, base) = (app.client.clone(), app.base.clone());
    let mut socket = Ws::try_connect(&base, "?topics=jobs", Some(WMS)).await.expect("the key is valid");
    assert_eq!(socket.json().await["type"], "snapshot");
    let mut kept = Ws::try_connect(&base, "?topics=config", Some(ADMIN)).await.expect("the key is valid");
    assert_eq!(kept.json().await["type"], "snapshot");

    let mut config = Config::load(&file).unwrap();
    config.auth.keys = vec![key("admin", Role::Admin, ADMIN), key("wms-2", Role::Viewer, WMS_2)];
    config.auth.max_failures = 2;
    std::fs::write(&file, toml::to_string(&config).unwrap()).unwrap();
    let (status, body) = reload(&http, &base, "").await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(
        body["auth"],
        json!({"keys": [{"name": "wms", "change": "removed"}, {"name": "wms-2", "change": "added"}],
               "settings": ["auth.max_failures"]})
    );
    assert!(
        matches!(socket.next(Duration::from_secs(5)).await, Got::Closed(1008)),
        "the removed key's socket"
    );
    assert_eq!(kept.json().await["type"], "config.reloaded", "another key's socket stays open");
    assert_eq!(Ws::try_connect(&base, "", Some(WMS)).await.err(), Some(401));
    assert_eq!(get(&http, &base, "/api/v1/whoami", WMS_2).await.1["role"], "viewer");

    // Keyless mode is decided at start: no reload empties the keys.
    let mut keyless = config.clone();
    keyless.auth.keys.clear();
    std::fs::write(&file, toml::to_string(&keyless).unwrap()).unwrap();
    let refused = reload(&http, &base, "?dry_run=true").await;
    assert_error(&refused, 409, "fixed_key");
    assert!(refused.1["error"]["message"].as_str().unwrap().starts_with("auth.keys: "), "{refused:?}");
    assert_error(&reload(&http, &base, "").await, 409, "fixed_key");
    assert_eq!(get(&http, &base, "/api/v1/whoami", ADMIN).await.0, 200, "the keys run on");

    // The new limit: two unknown keys (the revoked one counts) hold the address off.
    assert_error(&get(&http, &base, "/api/v1/jobs", "rk_revoke-guess-0123456789").await, 401, "unauthorized");
    assert_error(&get(&http, &base, "/api/v1/jobs", ADMIN).await, 429, "too_many_failures");
    kept.close().await;
    app.stop().await;
}
