//! Guessing keys: after `auth.max_failures` (10 by default) different unknown keys from one
//! address within `auth.failure_window_secs`, that address gets 429 with `Retry-After`, even
//! with the right key, until the window ends; other addresses are not touched, and neither a
//! stale key sent again nor a request without a key counts. (The window's end and the
//! bounded table are tested on paused time in `rackd::api::failures`.)

use std::net::{IpAddr, Ipv4Addr};

use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::store::Engine;

use crate::support::{TestApp, assert_error, spawn_with, split};

const KEY: &str = "rk_security-failures-viewer";

/// A client whose requests come from `127.0.0.N` (all of 127/8 is loopback on Linux).
fn from(n: u8) -> reqwest::Client {
    reqwest::Client::builder().local_address(IpAddr::V4(Ipv4Addr::new(127, 0, 0, n))).build().unwrap()
}

async fn jobs(app: &TestApp, client: &reqwest::Client, key: Option<&str>) -> reqwest::Response {
    let request = client.get(app.url("/api/v1/jobs"));
    let request = match key {
        Some(k) => request.bearer_auth(k),
        None => request,
    };
    request.send().await.unwrap()
}

#[tokio::test]
async fn ten_wrong_keys_hold_the_address_off_even_with_the_right_one() {
    let app = spawn_with(Engine::Sqlite, |c| {
        c.auth.keys = vec![KeyConfig { name: "hmi".into(), role: Role::Viewer, hash: KeyHash::of(KEY) }];
    })
    .await;
    let guesser = from(1);
    for n in 0..10 {
        let got = split(jobs(&app, &guesser, Some(&format!("rk_guess-{n}"))).await).await;
        assert_error(&got, 401, "unauthorized");
    }
    let held = jobs(&app, &guesser, Some(KEY)).await;
    let retry: u64 = held.headers()["retry-after"].to_str().unwrap().parse().unwrap();
    assert!((1..=60).contains(&retry), "Retry-After is the rest of the window in seconds: {retry}");
    assert_error(&split(held).await, 429, "too_many_failures");
    let on_ws = guesser.get(app.url("/api/v1/ws")).query(&[("token", KEY)]).send().await.unwrap();
    assert_eq!(on_ws.status(), 429, "every keyed route");
    let health = guesser.get(app.url("/healthz")).send().await.unwrap();
    assert_eq!(health.status(), 200, "the public routes stay open");

    // Another address is not touched.
    assert_eq!(jobs(&app, &from(2), Some(KEY)).await.status(), 200);

    // A stale key sent again and again is one failure; no key at all is none.
    let stale = from(3);
    for _ in 0..30 {
        assert_eq!(jobs(&app, &stale, Some("rk_revoked")).await.status(), 401);
        assert_eq!(jobs(&app, &stale, None).await.status(), 401);
    }
    assert_eq!(jobs(&app, &stale, Some(KEY)).await.status(), 200);
    app.stop().await;
}
