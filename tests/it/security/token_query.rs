//! `?token=` is taken on `GET /api/v1/ws` alone (a browser cannot set headers on a
//! WebSocket). Anywhere else a key in the query would end up in proxy logs and browser
//! history, and a POST with one could be a link: it is refused with 400 `token_in_query`,
//! not used, whatever the key. (The dashboard's side, asking before it adopts a key from
//! its own address, is in `browser::keys`.)

use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::store::Engine;

use crate::support::ws::Ws;
use crate::support::{assert_error, spawn_app, spawn_with, split};

const KEY: &str = "rk_security-token-operator";

#[tokio::test]
async fn a_key_in_the_query_is_refused_except_on_the_websocket() {
    let app = spawn_with(Engine::Sqlite, |c| {
        c.auth.keys = vec![KeyConfig { name: "wms".into(), role: Role::Operator, hash: KeyHash::of(KEY) }];
    })
    .await;
    // A link that would pause a device with the operator's key.
    let post = app.client.post(app.url(&format!("/api/v1/aisles/1/pause?token={KEY}"))).send().await.unwrap();
    assert_error(&split(post).await, 400, "token_in_query");
    let read = app.client.get(app.url(&format!("/api/v1/jobs?token={KEY}"))).send().await.unwrap();
    assert_error(&split(read).await, 400, "token_in_query");
    // Even beside a good key in the header: the URL is what leaks.
    let both = app.client.get(app.url("/api/v1/jobs?token=x")).bearer_auth(KEY).send().await.unwrap();
    assert_error(&split(both).await, 400, "token_in_query");
    let aisles = app.client.get(app.url("/api/v1/aisles")).bearer_auth(KEY).send().await.unwrap();
    let (_, aisles) = split(aisles).await;
    assert_eq!(aisles[0]["paused"], false, "nothing was paused: {aisles}");

    // The WebSocket takes it, and passes the rest of its query on.
    let mut ws = Ws::connect(&app.base, &format!("?topics=jobs&token={KEY}")).await;
    assert_eq!(ws.json().await["type"], "snapshot");
    assert_eq!(Ws::try_connect(&app.base, "?token=rk_wrong", None).await.err(), Some(401));
    app.stop().await;
}

#[tokio::test]
async fn without_keys_a_token_in_the_query_is_refused_too() {
    let app = spawn_app(Engine::Sqlite).await;
    let read = app.client.get(app.url("/api/v1/jobs?token=anything")).send().await.unwrap();
    assert_error(&split(read).await, 400, "token_in_query");
    let mut ws = Ws::connect(&app.base, "?token=anything").await;
    assert_eq!(ws.json().await["type"], "snapshot");
    app.stop().await;
}
