//! `POST /api/v1/config/reload`: the server started from a file (as `serve --config`), the
//! file rewritten, and the answer checked: the difference of a dry run, the refusals of a
//! bad key (as `check-config` words it) and of a key that cannot change at run time, the
//! admin role, and what a reload applies ([`apply`], [`handover`]). SQLite alone: a reload
//! reads files, and the store's part is the same code on both engines.

mod apply;

use std::path::Path;
use std::time::Duration;

use rackd::auth::KeyHash;
use rackd::config::{Config, Sources};
use serde_json::{Value, json};

use crate::support::node::Node;
use crate::support::*;

/// Two aisles of the demo site, a shelf and a crane (at addresses where nothing answers:
/// a dry run does not touch them), an admin and an operator key.
fn site(shelf_address: &str, extra: &str) -> String {
    format!(
        r#"
[[auth.keys]]
name = "admin"
role = "admin"
hash = "{admin}"

[[auth.keys]]
name = "ops"
role = "operator"
hash = "{ops}"

[[site.aisles]]
aisle = 1
rows = 2
bays = 10
levels = 6
positions = 4

[[site.aisles]]
aisle = 2
rows = 2
bays = 20
levels = 8
positions = 2
depth = 2

[[devices]]
id = "shelf-1"
kind = "shelf"
address = "{shelf_address}"
aisles = [1]

{extra}
"#,
        admin = KeyHash::of("key-admin"),
        ops = KeyHash::of("key-ops"),
    )
}

const CRANE: &str = r#"
[[devices]]
id = "crane-2"
kind = "crane"
address = "127.0.0.1:9"
aisles = [2]
"#;

/// Writes `text` to `file` with the running file's listen address and database, as an
/// operator editing the site's part of it would.
fn rewrite(file: &Path, text: &str, edit: impl FnOnce(&mut Config)) {
    let running = Config::load(file).unwrap();
    let mut config = Config::parse(text, file).unwrap();
    config.server.listen = running.server.listen;
    config.database = running.database;
    edit(&mut config);
    std::fs::write(file, toml::to_string(&config).unwrap()).unwrap();
}

/// The difference in a reload's answer (without the running configuration's hash and time).
fn difference(body: &Value) -> Value {
    let mut body = body.clone();
    for key in ["hash", "loaded_at", "kept_for_takeover"] {
        body.as_object_mut().map(|o| o.remove(key));
    }
    body
}

/// A GET with the admin's key.
async fn get(app: &TestApp, path: &str) -> (u16, Value) {
    split(app.client.get(app.url(path)).bearer_auth("key-admin").send().await.unwrap()).await
}

async fn reload(app: &TestApp, query: &str, key: &str) -> (u16, Value) {
    let url = app.url(&format!("/api/v1/config/reload{query}"));
    // Keyless mode takes a POST with a JSON content type only (`api::keyless`).
    let request = app.client.post(url).header("content-type", "application/json");
    split(request.bearer_auth(key).send().await.unwrap()).await
}

#[tokio::test]
async fn a_dry_run_answers_the_difference_and_applies_nothing() {
    let (app, file) = spawn_from_file(&site("127.0.0.1:9", CRANE)).await;
    let running = get(&app, "/api/v1/config").await.1;
    let (status, body) = reload(&app, "?dry_run=true", "key-admin").await;
    assert_eq!(
        (status, difference(&body)),
        (
            200,
            json!({"dry_run": true, "devices": [], "aisles": {"added": [], "removed": [], "changed": []},
                "auth": {"keys": [], "settings": []}, "fixed": []})
        )
    );
    assert_eq!((&body["hash"], &body["loaded_at"]), (&running["hash"], &running["loaded_at"]));
    assert_eq!(running["hash"].as_str().map(str::len), Some(64), "{running}");

    let third = r#"
[[site.aisles]]
aisle = 3
rows = 1
bays = 5
levels = 2
positions = 4

[[devices]]
id = "shelf-3"
kind = "shelf"
address = "127.0.0.1:9"
aisles = [3]
"#;
    rewrite(&file, &site("127.0.0.1:19", third), |_| {});
    let expected = json!({
        "dry_run": true,
        "devices": [
            {"id": "shelf-1", "change": "changed", "keys": ["address"]},
            {"id": "crane-2", "change": "removed"},
            {"id": "shelf-3", "change": "added"},
        ],
        "aisles": {"added": [3], "removed": [], "changed": []},
        "auth": {"keys": [], "settings": []},
        "fixed": [],
    });
    let (status, body) = reload(&app, "?dry_run=true", "key-admin").await;
    assert_eq!((status, difference(&body)), (200, expected.clone()));
    // Nothing was applied: the same answer again, against the same running configuration.
    let (status, body) = reload(&app, "?dry_run=true", "key-admin").await;
    assert_eq!((status, difference(&body)), (200, expected.clone()));
    assert_eq!(get(&app, "/api/v1/config").await.1, running);
    // Operators run the site; its configuration is the administrators'.
    assert_error(&reload(&app, "?dry_run=true", "key-ops").await, 403, "forbidden");
    assert_error(&reload(&app, "", "key-ops").await, 403, "forbidden");
    assert_error(&reload(&app, "?dry_run=true", "nobody").await, 401, "unauthorized");

    // Applied: the same difference, and the new configuration runs.
    let (status, body) = reload(&app, "?dry_run=false", "key-admin").await;
    let mut applied = expected.clone();
    applied["dry_run"] = json!(false);
    assert_eq!((status, difference(&body)), (200, applied));
    let now = get(&app, "/api/v1/config").await.1;
    assert_eq!(now["hash"], body["hash"]);
    assert_ne!(now["hash"], running["hash"]);
    let (_, devices) = get(&app, "/api/v1/devices").await;
    let ids: Vec<&str> = devices.as_array().unwrap().iter().map(|d| d["id"].as_str().unwrap()).collect();
    assert_eq!(ids, ["shelf-1", "shelf-3"]);
    let (_, aisles) = get(&app, "/api/v1/aisles").await;
    assert!(aisles.to_string().contains("\"aisle\":3"), "the added aisle is there: {aisles}");
    let (_, places) = get(&app, "/api/v1/locations?aisle=3").await;
    assert!(places.to_string().contains("\"aisle\":3"), "with its locations: {places}");
    let (status, body) = reload(&app, "", "key-admin").await;
    assert_eq!((status, &body["devices"]), (200, &json!([])), "nothing left to change");
    app.stop().await;
}

#[tokio::test]
async fn a_bad_key_is_refused_as_check_config_words_it() {
    let (app, file) = spawn_from_file(&site("127.0.0.1:9", CRANE)).await;
    let mut text = std::fs::read_to_string(&file).unwrap();
    text = text.replacen("[server]\n", "[server]\nlisen = \"127.0.0.1:1\"\n", 1);
    std::fs::write(&file, &text).unwrap();
    let checked = Sources::file(&file).load().unwrap_err().to_string();
    assert!(checked.contains("rackd.toml:") && checked.contains("server.lisen"), "{checked}");

    let refused = reload(&app, "?dry_run=true", "key-admin").await;
    assert_error(&refused, 422, "invalid_config");
    assert_eq!(refused.1["error"]["message"], checked.as_str());
    // Whether or not it is a dry run: nothing is applied from a file that does not check,
    // not even the device changed beside the bad key.
    let before = get(&app, "/api/v1/config").await.1;
    std::fs::write(&file, text.replace("127.0.0.1:9\"", "127.0.0.1:19\"")).unwrap();
    let refused = reload(&app, "", "key-admin").await;
    assert_error(&refused, 422, "invalid_config");
    assert!(refused.1["error"]["message"].as_str().unwrap().contains("server.lisen"), "{refused:?}");
    assert_eq!(get(&app, "/api/v1/config").await.1, before);
    let (_, shelf) = get(&app, "/api/v1/devices/shelf-1").await;
    assert_eq!(shelf["address"], "127.0.0.1:9", "{shelf}");
    app.stop().await;
}

#[tokio::test]
async fn a_key_that_cannot_change_at_run_time_is_refused_by_name_and_place() {
    let (app, file) = spawn_from_file(&site("127.0.0.1:9", CRANE)).await;
    // With a device change beside it: all or nothing.
    rewrite(&file, &site("127.0.0.1:19", CRANE), |c| c.server.listen = "127.0.0.1:1".parse().unwrap());
    let refused = reload(&app, "?dry_run=true", "key-admin").await;
    assert_error(&refused, 409, "fixed_key");
    let message = refused.1["error"]["message"].as_str().unwrap();
    let line =
        std::fs::read_to_string(&file).unwrap().lines().position(|l| l.starts_with("listen =")).unwrap() + 1;
    let place = format!("server.listen ({}:{line}:", file.display());
    assert!(message.starts_with(&place), "{message} should start with {place}");
    assert!(message.contains("nothing was applied"), "{message}");
    assert_error(&reload(&app, "", "key-admin").await, 409, "fixed_key");
    let (_, shelf) = get(&app, "/api/v1/devices/shelf-1").await;
    assert_eq!(shelf["address"], "127.0.0.1:9", "the device beside it did not change: {shelf}");
    app.stop().await;
}

#[tokio::test]
async fn a_server_not_started_from_a_file_has_nothing_to_reload() {
    let app = spawn_app(rackd::store::Engine::Sqlite).await;
    assert_error(&reload(&app, "?dry_run=true", "none").await, 409, "no_config_file");
    app.stop().await;
}

/// SIGHUP reloads a `rackd serve --config` process as the API does, logs its outcome, and
/// does not end the process.
#[tokio::test]
async fn sighup_reloads_the_file_and_logs_the_outcome() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = Config::demo();
    config.server.listen = "127.0.0.1:0".parse().unwrap();
    config.database.path = dir.path().join("rackd.db");
    let mut node = Node::new(dir.path(), "rackd", &config);
    node.start();
    let http = reqwest::Client::new();
    let health = format!("{}/healthz", node.url);
    eventually("rackd to answer", Duration::from_secs(30), async || {
        http.get(&health).send().await?.error_for_status()
    })
    .await;
    let loaded = |http: reqwest::Client, url: String| async move {
        let body: Value =
            http.get(format!("{url}/api/v1/config")).send().await.unwrap().json().await.unwrap();
        body["hash"].as_str().unwrap().to_owned()
    };
    let before = loaded(http.clone(), node.url.clone()).await;

    let mut third = config.site.aisles[0].clone();
    third.aisle = 3;
    config.site.aisles.push(third);
    std::fs::write(node.config_file(), toml::to_string(&config).unwrap()).unwrap();
    node.hang_up();
    eventually("the reload in the log", Duration::from_secs(10), async || {
        let log = node.log();
        let line = log.lines().find(|l| l.contains("SIGHUP: the configuration was reloaded"));
        line.filter(|l| l.contains(r#""added":[3]"#)).map(str::to_owned).ok_or(log)
    })
    .await;
    assert_eq!(loaded(http.clone(), node.url.clone()).await, config.site_hash());
    assert_ne!(config.site_hash(), before);

    config.events.buffer += 1;
    std::fs::write(node.config_file(), toml::to_string(&config).unwrap()).unwrap();
    node.hang_up();
    eventually("the refusal of a fixed key in the log", Duration::from_secs(10), async || {
        let log = node.log();
        let refused = log.lines().any(|l| l.contains("is refused") && l.contains("events.buffer"));
        if refused { Ok(()) } else { Err(log) }
    })
    .await;

    let text = std::fs::read_to_string(node.config_file()).unwrap();
    std::fs::write(node.config_file(), text.replacen("[server]\n", "[server]\nlisen = 1\n", 1)).unwrap();
    let checked = Sources::file(node.config_file()).load().unwrap_err().to_string();
    node.hang_up();
    eventually("the refusal in the log", Duration::from_secs(10), async || {
        let log = node.log();
        let refused = log.lines().any(|l| l.contains("is refused") && l.contains(&checked));
        if refused { Ok(()) } else { Err(log) }
    })
    .await;
    assert!(node.running(), "a SIGHUP does not end rackd");
    http.get(&health).send().await.unwrap().error_for_status().unwrap();
}

/// An aisle removed, or shrunk, is refused while a box or an unfinished job uses a
/// location it would lose, naming them; one that nothing uses is not.
#[tokio::test]
async fn an_aisle_in_use_is_not_removed_and_what_holds_it_is_named() {
    let (app, file) = spawn_from_file(&site("127.0.0.1:9", CRANE)).await;
    let without_2 = |c: &mut Config| {
        c.site.aisles.retain(|a| a.aisle != 2);
        c.devices.retain(|d| d.aisles() != [2]);
    };
    rewrite(&file, &site("127.0.0.1:9", ""), without_2);
    let (status, body) = reload(&app, "?dry_run=true", "key-admin").await;
    assert_eq!((status, &body["aisles"]["removed"]), (200, &json!([2])), "{body}");

    let stock = json!({"locations": [
        {"aisle": 2, "row": 1, "bay": 4, "level": 2, "position": 1, "occupied": true, "barcode": "BOX-9"}
    ]});
    let put = app.client.put(app.url("/api/v1/locations")).bearer_auth("key-admin").json(&stock);
    let (status, body) = split(put.send().await.unwrap()).await;
    assert!(status < 300, "{status} {body}");
    let refused = reload(&app, "?dry_run=true", "key-admin").await;
    assert_error(&refused, 409, "aisle_in_use");
    let message = refused.1["error"]["message"].as_str().unwrap();
    assert!(message.contains("aisle 2 would lose locations in use: box BOX-9 at 2-1-4-2-1"), "{message}");

    // A job queued on the shelf (which nothing answers for) holds bay 3 of aisle 1.
    let job = json!({"kind": "store", "reference": "R-1", "barcode": "BOX-1", "to": loc(1, 3, 1, 1)});
    let post = app.client.post(app.url("/api/v1/jobs")).bearer_auth("key-ops").json(&job);
    let (status, created) = split(post.send().await.unwrap()).await;
    assert_eq!(status, 201, "{created}");
    let id = created["id"].as_i64().unwrap();
    rewrite(&file, &site("127.0.0.1:9", CRANE), |c| c.site.aisles[0].bays = 2);
    let refused = reload(&app, "?dry_run=true", "key-admin").await;
    assert_error(&refused, 409, "aisle_in_use");
    let message = refused.1["error"]["message"].as_str().unwrap();
    assert!(message.contains("aisle 1") && message.contains(&format!("job {id} at ")), "{message}");
    assert!(!message.contains("BOX-9"), "aisle 2 stays: {message}");
    // Shrunk so that bay 3 stays: nothing it loses is in use.
    rewrite(&file, &site("127.0.0.1:9", CRANE), |c| c.site.aisles[0].bays = 3);
    let (status, body) = reload(&app, "?dry_run=true", "key-admin").await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["aisles"]["changed"], json!([{"aisle": 1, "keys": ["bays"]}]));
    // Applied: the bays it loses leave the store; the job's bay stays, and the job with it.
    let (status, body) = reload(&app, "", "key-admin").await;
    assert_eq!(status, 200, "{body}");
    let (_, places) = get(&app, "/api/v1/locations?aisle=1").await;
    let bays: std::collections::BTreeSet<u64> =
        places.as_array().unwrap().iter().map(|l| l["bay"].as_u64().unwrap()).collect();
    assert_eq!(bays, [1, 2, 3].into(), "{places}");
    let (_, job) = get(&app, &format!("/api/v1/jobs/{id}")).await;
    assert_eq!(job["state"], "queued", "{job}");
    app.stop().await;
}
