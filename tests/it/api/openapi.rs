//! The committed OpenAPI document matches the code, and every request example in it is a
//! valid request against the demo site (with its simulated light tower for tag writes).

use rackd::store::Engine;

use crate::support::*;

#[test]
fn committed_openapi_matches_the_code() {
    let generated = rackd::api::openapi().to_pretty_json().unwrap();
    let committed =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json")).unwrap();
    assert!(
        committed.trim_end() == generated.trim_end(),
        "openapi/openapi.json is stale: run `cargo run -- openapi > openapi/openapi.json`"
    );
}

#[tokio::test]
async fn every_request_example_is_accepted_by_the_demo_site() {
    let tower = rackd::sim::tower::TowerSim::start("127.0.0.1:0", None).await.unwrap();
    let device = rackd::cli::demo::tower_device("tower1", &tower.local_addr().to_string());
    let webhook =
        rackd::config::WebhookConfig::new("wms", "http://127.0.0.1:9/", &["job.*"], receiver::SECRET);
    let app = spawn_with(Engine::Sqlite, |c| {
        c.devices = vec![device];
        c.webhooks = vec![webhook];
    })
    .await;
    // Tag writes need the device online, which its first poll makes it.
    eventually("the tower to come online", std::time::Duration::from_secs(5), async || {
        app.get("/api/v1/devices/tower1").await.1["online"] == true
    })
    .await;
    // `{name}` is `wms`: the webhook's, and a sequence's.
    let member = serde_json::json!({"kind": "travel", "to": {"aisle": 1, "row": 1, "bay": 1, "level": 1, "position": 1},
        "sequence": {"name": "wms", "position": 1}});
    let (status, joined) = app.post("/api/v1/jobs", &member).await;
    assert_eq!(status, 201, "{joined}");
    let doc: serde_json::Value = serde_json::from_str(&rackd::api::openapi().to_json().unwrap()).unwrap();
    let mut tried = 0;
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let Some(schema_ref) = op.pointer("/requestBody/content/application~1json/schema/$ref") else {
                continue;
            };
            let name = schema_ref.as_str().unwrap().rsplit('/').next().unwrap();
            let example = &doc["components"]["schemas"][name]["example"];
            assert!(!example.is_null(), "{method} {path}: schema {name} has no example");
            // Make sure a job exists for the example's path parameters.
            let (_, job) = app.post("/api/v1/jobs", &store(&format!("example-{tried}"))).await;
            let path = match path.strip_prefix("/api/v1/devices/{id}/tags/") {
                Some("{tag}") => "/api/v1/devices/tower1/tags/tower.green".to_owned(),
                _ => ["{aisle}", "{row}", "{bay}", "{level}", "{position}"]
                    .iter()
                    .fold(path.replace("{id}", &job["id"].to_string()), |p, k| p.replace(k, "1"))
                    .replace("{name}", "wms"),
            };
            let r = app
                .client
                .request(method.to_uppercase().parse().unwrap(), app.url(&path))
                .json(example)
                .send()
                .await
                .unwrap();
            let (status, body) = split(r).await;
            assert!((200..300).contains(&status), "{method} {path} with {example}: {status} {body}");
            tried += 1;
        }
    }
    assert!(tried >= 3, "request bodies found: {tried}");
}
