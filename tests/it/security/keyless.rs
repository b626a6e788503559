//! Keyless mode (no `[[auth.keys]]`: the demo, `--insecure`) against a hostile web page the
//! local user opens: a cross-site POST (with and without CORS's blessing), a DNS-rebinding
//! page (its own name in `Host`), a cross-site WebSocket, and a `text/plain` POST, which a
//! form or a `no-cors` fetch sends without asking. Each is refused, and nothing changes;
//! the same requests from rackd's own page, or a host listed in `server.allowed_hosts`,
//! still work; with keys configured nothing of this applies.

use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::store::Engine;
use reqwest::header::{CONTENT_TYPE, HOST, ORIGIN};
use serde_json::Value;

use crate::support::ws::Ws;
use crate::support::{TestApp, assert_error, spawn_app, spawn_with, split};

const PAUSE: &str = "/api/v1/aisles/1/pause";

/// `host:port` of the server.
fn authority(app: &TestApp) -> String {
    app.base.trim_start_matches("http://").to_owned()
}

fn port(app: &TestApp) -> u16 {
    authority(app).rsplit_once(':').unwrap().1.parse().unwrap()
}

/// Whether aisle 1 is paused now.
async fn paused(app: &TestApp) -> bool {
    let (status, aisles) = app.get("/api/v1/aisles").await;
    assert_eq!(status, 200, "{aisles}");
    aisles.as_array().unwrap().iter().any(|a| a["aisle"] == 1 && a["paused"] == true)
}

/// A POST of the pause, with these headers and body.
async fn pause(app: &TestApp, headers: &[(reqwest::header::HeaderName, &str)], body: &str) -> (u16, Value) {
    let mut request = app.client.post(app.url(PAUSE)).body(body.to_owned());
    for (name, value) in headers {
        request = request.header(name, *value);
    }
    split(request.send().await.unwrap()).await
}

#[tokio::test]
async fn a_cross_site_page_cannot_act_read_or_listen_without_keys() {
    let app = spawn_app(Engine::Sqlite).await;
    let json = (CONTENT_TYPE, "application/json");
    let evil = (ORIGIN, "http://evil.example");

    // A cross-origin POST, even as JSON (a page that got a preflight through somehow).
    let got = pause(&app, &[json.clone(), evil.clone()], r#"{"reason": "pwned"}"#).await;
    assert_error(&got, 403, "origin_not_allowed");
    // Another local page (a dev server on another port) is another origin too.
    let other_port = format!("http://localhost:{}", port(&app) + 1);
    let got = pause(&app, &[json.clone(), (ORIGIN, &other_port)], "").await;
    assert_error(&got, 403, "origin_not_allowed");
    assert_error(&pause(&app, &[json.clone(), (ORIGIN, "null")], "").await, 403, "origin_not_allowed");

    // A form or a `no-cors` fetch: `text/plain` (or no type at all), body or not.
    let got = pause(&app, &[(CONTENT_TYPE, "text/plain")], r#"{"reason": "pwned"}"#).await;
    assert_error(&got, 415, "unsupported_media_type");
    let got = split(app.client.post(app.url("/api/v1/jobs/1/cancel")).send().await.unwrap()).await;
    assert_error(&got, 415, "unsupported_media_type");
    let form = app.client.post(app.url("/api/v1/jobs")).form(&[("kind", "store")]).send().await.unwrap();
    assert_error(&split(form).await, 415, "unsupported_media_type");

    // A DNS-rebinding page: its own name, now pointing at 127.0.0.1, in `Host`; reading
    // and changing alike.
    let rebound = format!("evil.example:{}", port(&app));
    let read = app.client.get(app.url("/api/v1/jobs")).header(HOST, &rebound).send().await.unwrap();
    assert_error(&split(read).await, 421, "host_not_allowed");
    let metrics = app.client.get(app.url("/metrics")).header(HOST, &rebound).send().await.unwrap();
    assert_error(&split(metrics).await, 421, "host_not_allowed");
    let got = pause(&app, &[json.clone(), (HOST, &rebound)], "").await;
    assert_error(&got, 421, "host_not_allowed");

    // A cross-site WebSocket (a browser sends its page's origin with the handshake).
    let refused = Ws::try_connect_with(&app.base, "", &[("origin", "http://evil.example")]).await;
    assert_eq!(refused.err(), Some(403), "a cross-site WebSocket is refused");
    let refused = Ws::try_connect_with(&app.base, "", &[("host", &rebound)]).await;
    assert_eq!(refused.err(), Some(421), "a rebound WebSocket is refused");

    assert!(!paused(&app).await, "none of it paused the aisle");

    // rackd's own page: its origin is the host it was loaded from.
    let own = format!("http://{}", authority(&app));
    let got = pause(&app, &[json.clone(), (ORIGIN, &own)], r#"{"reason": "from the dashboard"}"#).await;
    assert_eq!(got.0, 200, "{got:?}");
    assert!(paused(&app).await);
    let localhost = format!("localhost:{}", port(&app));
    let got = app.client.get(app.url("/api/v1/jobs")).header(HOST, &localhost).send().await.unwrap();
    assert_eq!(got.status(), 200);
    let mut ws = Ws::try_connect_with(&app.base, "", &[("origin", &own)]).await.expect("its own WebSocket");
    assert_eq!(ws.json().await["type"], "snapshot");
    // Programs other than browsers send no `Origin`, and JSON: as before.
    let (status, _) = app.post("/api/v1/aisles/1/resume", &serde_json::json!({})).await;
    assert_eq!(status, 200);
    // The public routes answer probes whatever name they use.
    let probe = app.client.get(app.url("/healthz")).header(HOST, "10.9.8.7:1").send().await.unwrap();
    assert_eq!(probe.status(), 200);
    app.stop().await;
}

#[tokio::test]
async fn a_host_in_allowed_hosts_may_call_and_be_the_origin() {
    let app =
        spawn_with(Engine::Sqlite, |c| c.server.allowed_hosts = vec!["WCS.plant.local".parse().unwrap()])
            .await;
    let named = format!("wcs.plant.local:{}", port(&app));
    let got = pause(
        &app,
        &[(CONTENT_TYPE, "application/json"), (HOST, &named), (ORIGIN, "http://wcs.plant.local")],
        "",
    )
    .await;
    assert_eq!(got.0, 200, "{got:?}");
    let ws =
        Ws::try_connect_with(&app.base, "", &[("host", &named), ("origin", "https://wcs.plant.local")]).await;
    assert!(ws.is_ok(), "{:?}", ws.err());
    let other = format!("other.plant.local:{}", port(&app));
    let got = pause(&app, &[(CONTENT_TYPE, "application/json"), (HOST, &other)], "").await;
    assert_error(&got, 421, "host_not_allowed");
    app.stop().await;
}

#[tokio::test]
async fn with_keys_the_key_is_the_defence_and_nothing_else_changes() {
    const KEY: &str = "rk_security-keyless-operator";
    let app = spawn_with(Engine::Sqlite, |c| {
        c.auth.keys = vec![KeyConfig { name: "wms".into(), role: Role::Operator, hash: KeyHash::of(KEY) }];
    })
    .await;
    let bearer = format!("Bearer {KEY}");
    let auth = (reqwest::header::AUTHORIZATION, bearer.as_str());
    let rebound = format!("evil.example:{}", port(&app));
    // An empty POST with no type, from any origin and under any name: as before.
    let got = pause(&app, &[auth.clone(), (ORIGIN, "http://evil.example"), (HOST, &rebound)], "").await;
    assert_eq!(got.0, 200, "{got:?}");
    let got =
        split(app.client.post(app.url("/api/v1/jobs/999/cancel")).bearer_auth(KEY).send().await.unwrap())
            .await;
    assert_error(&got, 404, "not_found");
    let ws =
        Ws::try_connect_with(&app.base, "", &[("origin", "http://evil.example"), ("authorization", &bearer)])
            .await;
    assert!(ws.is_ok(), "{:?}", ws.err());
    app.stop().await;
}
