//! The auth matrix: each role against each route group, missing and wrong keys, and the
//! loopback rule without keys.

use rackd::app::Application;
use rackd::auth::{KeyHash, Role};
use rackd::config::{Config, KeyConfig};
use rackd::store::Engine;
use rstest::rstest;
use serde_json::json;

use crate::support::*;

fn key(name: &str, role: Role) -> KeyConfig {
    KeyConfig { name: name.into(), role, hash: KeyHash::of(&format!("key-{name}")) }
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn each_role_reaches_exactly_its_routes(#[case] engine: Engine) {
    let app = spawn_with(engine, |c| {
        c.auth.keys = vec![key("v", Role::Viewer), key("o", Role::Operator), key("a", Role::Admin)];
    })
    .await;
    // (method, path, body, lowest role allowed); None = public.
    let routes: Vec<(&str, &str, Option<serde_json::Value>, Option<Role>)> = vec![
        ("GET", "/healthz", None, None),
        ("GET", "/readyz", None, None),
        ("GET", "/openapi.json", None, None),
        ("GET", "/api/v1/jobs", None, Some(Role::Viewer)),
        ("GET", "/metrics", None, Some(Role::Viewer)),
        ("POST", "/api/v1/jobs", Some(store("AUTH-1")), Some(Role::Operator)),
        ("POST", "/api/v1/jobs/batch", Some(json!({"jobs": [store("AUTH-2")]})), Some(Role::Operator)),
        ("PATCH", "/api/v1/jobs/1", Some(json!({"priority": 1})), Some(Role::Operator)),
        ("POST", "/api/v1/jobs/1/cancel", None, Some(Role::Operator)),
        ("POST", "/api/v1/jobs/1/retry", None, Some(Role::Operator)),
        ("POST", "/api/v1/aisles/1/pause", None, Some(Role::Operator)),
        ("POST", "/api/v1/locations/1/1/1/1/1/lock", Some(json!({"reason": "auth"})), Some(Role::Operator)),
        ("POST", "/api/v1/locations/1/1/1/1/1/unlock", None, Some(Role::Operator)),
        (
            "PUT",
            "/api/v1/locations",
            Some(
                json!({"locations": [{"aisle": 1, "row": 1, "bay": 1, "level": 1, "position": 1, "occupied": false}]}),
            ),
            Some(Role::Admin),
        ),
        ("GET", "/api/v1/audit", None, Some(Role::Viewer)),
        ("GET", "/api/v1/aisles", None, Some(Role::Viewer)),
        ("GET", "/api/v1/alarms", None, Some(Role::Viewer)),
        // A method the route lacks: the key is checked first, so strangers learn nothing.
        ("POST", "/api/v1/alarms", None, Some(Role::Operator)),
    ];
    let callers: [(Option<&str>, Option<Role>); 5] = [
        (None, None),
        (Some("wrong"), None),
        (Some("key-v"), Some(Role::Viewer)),
        (Some("key-o"), Some(Role::Operator)),
        (Some("key-a"), Some(Role::Admin)),
    ];
    for (method, path, body, needed) in &routes {
        for (presented, role) in &callers {
            let mut req = app.client.request(method.parse().unwrap(), app.url(path));
            if let Some(k) = presented {
                req = req.bearer_auth(k);
            }
            if let Some(b) = body {
                req = req.json(b);
            }
            let got = split(req.send().await.unwrap()).await;
            match (needed, role) {
                (None, _) => assert_eq!(got.0, 200, "{method} {path} is public"),
                (Some(_), None) => assert_error(&got, 401, "unauthorized"),
                (Some(n), Some(r)) if r < n => assert_error(&got, 403, "forbidden"),
                (Some(_), Some(_)) => assert!(
                    ![401, 403].contains(&got.0) && got.0 < 500,
                    "{method} {path} as {presented:?}: {got:?}"
                ),
            }
        }
    }
    let r = app.client.get(app.url("/api/v1/jobs")).header("x-api-key", "key-v").send().await.unwrap();
    assert_eq!(r.status(), 200, "X-Api-Key works too");
    let r = app.client.get(app.url("/api/v1/jobs")).send().await.unwrap();
    assert_eq!(r.headers()["www-authenticate"], "Bearer");
    let r =
        app.client.get(app.url("/api/v1/jobs")).header("authorization", "bearer key-v").send().await.unwrap();
    assert_eq!(r.status(), 200, "the scheme is case-insensitive");
    // `?token=` is the WebSocket's alone (issue 41): anywhere else it is refused, good key
    // or not, rather than used or dropped (`security::token_query`).
    for path in [
        "/api/v1/jobs?token=key-v&limit=5",
        "/api/v1/alarms?token=key-v",
        "/api/v1/locations?token=key-v&aisle=1",
        "/api/v1/audit?token=key-v",
        "/api/v1/jobs?token=nope",
    ] {
        assert_error(
            &split(app.client.get(app.url(path)).send().await.unwrap()).await,
            400,
            "token_in_query",
        );
    }
    // The audit names the key that acted.
    let r = app.client.post(app.url("/api/v1/aisles/1/pause")).bearer_auth("key-o").send().await.unwrap();
    assert_eq!(r.status(), 200);
    let (_, audit) =
        split(app.client.get(app.url("/api/v1/audit?limit=1")).bearer_auth("key-v").send().await.unwrap())
            .await;
    assert_eq!(
        (audit["entries"][0]["by"].clone(), audit["entries"][0]["action"].clone()),
        (json!("o"), json!("pause"))
    );
}

/// Refused before any store is opened: one engine is enough.
#[tokio::test]
async fn without_keys_only_loopback_is_served() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = Config::demo();
    config.database.path = dir.path().join("db");
    config.server.listen = "0.0.0.0:0".parse().unwrap();
    let err = Application::build(&config, false).await.err().expect("refused");
    assert!(err.to_string().contains("--insecure"), "{err}");
    assert!(Application::build(&config, true).await.is_ok(), "--insecure allows it");
    config.auth.keys = vec![key("a", Role::Admin)];
    assert!(Application::build(&config, false).await.is_ok(), "keys allow it");
}
