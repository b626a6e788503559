//! The Webhooks panel: a subscription to a URL nothing listens on shows `failing` with its
//! error and how far behind it is once a job is posted, its delivery log lists the failed
//! tries, and an administrator pauses and resumes it from the page (a refused replay shows
//! as the page's other refused actions do); nothing scrolls sideways on a tablet; an
//! operator's key shows none of those buttons.

use rackd::auth::{KeyHash, Role};
use rackd::config::{KeyConfig, WebhookConfig};
use serde_json::json;

use super::{Browser, demo_app};
use crate::support::loc;

const ADMIN: &str = "rk_browser-webhooks-admin";
const OPERATOR: &str = "rk_browser-webhooks-operator";

/// The tile of subscription `wms`.
const TILE: &str = "#webhooks [data-webhook=\"wms\"]";

#[tokio::test]
async fn the_webhooks_panel_shows_a_failing_subscription_and_its_log() {
    let Some(browser) = Browser::start().await else { return };
    let (app, _sims) = demo_app(|c| {
        c.auth.keys = vec![
            KeyConfig { name: "root".into(), role: Role::Admin, hash: KeyHash::of(ADMIN) },
            KeyConfig { name: "olga".into(), role: Role::Operator, hash: KeyHash::of(OPERATOR) },
        ];
        // Port 9 (discard): nothing listens, every try fails at once.
        let mut wms = WebhookConfig::new(
            "wms",
            "http://127.0.0.1:9/",
            &["job.*"],
            "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw",
        );
        wms.backoff_ms = 100;
        wms.max_backoff_ms = 300;
        wms.timeout_ms = 1000;
        c.webhooks = vec![wms];
    })
    .await;
    browser.viewport(1600, 1000).await;
    browser.open_with_key(&app, ADMIN).await;
    browser.wait("whoami", "return document.getElementById('who').textContent === 'root · admin'", 15).await;
    browser
        .wait(
            "the Webhooks panel with its subscription",
            &format!("return !document.getElementById('webhooks-panel').hidden && document.querySelector('{TILE}') !== null"),
            15,
        )
        .await;
    let url = browser.text(&format!("{TILE} .webhook-url")).await;
    assert_eq!(url, json!("http://127.0.0.1:9/"));

    // A job: its events cannot be delivered, and the tile says so, with the error.
    let response = app
        .client
        .post(app.url("/api/v1/jobs"))
        .bearer_auth(ADMIN)
        .json(&json!({"kind": "store", "barcode": "BOX-W1", "to": loc(1, 1, 1, 1)}))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), 201);
    let failing = format!(
        "const t = document.querySelector('{TILE}');
         return t.classList.contains('is-failing') && t.querySelector('.webhook-state').textContent === 'failing'
             && !t.querySelector('.webhook-error').hidden
             && [t.querySelector('.webhook-error').textContent, t.querySelector('.webhook-behind').textContent];"
    );
    let shown = browser.wait("the subscription failing, with its error", &failing, 30).await;
    let (error, behind) = (shown[0].as_str().unwrap(), shown[1].as_str().unwrap());
    assert!(error.starts_with("Last error ") && error.contains("failing since"), "{error}");
    assert!(behind.contains("event") && behind.contains("oldest"), "events and seconds behind: {behind}");
    assert_eq!(browser.text("#webhook-summary").await, json!("1 failing"));

    // The delivery log: the failed tries, newest first.
    browser.click(&format!("{TILE} .webhook-log summary")).await;
    let script = format!(
        "const rows = [...document.querySelectorAll('{TILE} table.deliveries tbody tr')];
         return rows.length >= 2 && rows.map(r => [...r.cells].map(c => c.textContent));"
    );
    let rows = browser.wait("the delivery log's failed tries", &script, 15).await;
    let first = rows[0].as_array().unwrap();
    assert_eq!(first[4], json!("failed"), "outcome: {first:?}");
    assert_eq!(first[3], json!("–"), "no HTTP status without an answer: {first:?}");
    assert!(first[6].as_str().is_some_and(|e| !e.is_empty()), "the error: {first:?}");
    browser.screenshot("dashboard-webhooks.png").await;

    // On a tablet the tile, its log and its buttons fit the width.
    browser.viewport(800, 1200).await;
    let fits = browser.js("return document.documentElement.scrollWidth <= window.innerWidth").await;
    assert_eq!(fits, json!(true), "nothing scrolls sideways on a tablet");
    browser.screenshot("dashboard-webhooks-tablet.png").await;
    browser.viewport(1600, 1000).await;

    // Pause, then Resume (each a second click), from the page.
    let visible = |css: &str| {
        format!("const b = document.querySelector('{TILE} {css}'); return b && b.offsetParent !== null")
    };
    browser.wait("the Pause button", &visible("button.pause"), 10).await;
    browser.click(&format!("{TILE} button.pause")).await;
    browser.click(&format!("{TILE} button.pause")).await;
    let paused = format!(
        "const t = document.querySelector('{TILE}'); return t.classList.contains('is-paused') && t.querySelector('.webhook-state').textContent === 'paused'"
    );
    browser.wait("the subscription paused", &paused, 10).await;
    let list = app.client.get(app.url("/api/v1/webhooks")).bearer_auth(ADMIN).send().await.unwrap();
    let list: serde_json::Value = list.json().await.unwrap();
    assert_eq!(list["webhooks"][0]["state"], json!("paused"));
    browser.click(&format!("{TILE} button.resume")).await;
    browser.click(&format!("{TILE} button.resume")).await;
    browser
        .wait(
            "the subscription resumed",
            &format!("return !document.querySelector('{TILE}').classList.contains('is-paused')"),
            10,
        )
        .await;

    // A replay from an event the log does not hold is refused, and the page says so.
    browser.js(&format!("document.querySelector('{TILE} .webhook-seq').value = '999999'")).await;
    browser.click(&format!("{TILE} button.replay")).await;
    browser.click(&format!("{TILE} button.replay")).await;
    let toast = browser
        .wait(
            "the refused replay's message",
            "const t = [...document.querySelectorAll('#toasts .toast')].find(t => t.textContent.startsWith('Replay webhook wms: ')); return t && t.textContent",
            10,
        )
        .await;
    assert!(toast.as_str().is_some_and(|t| t.len() > "Replay webhook wms: ".len()), "{toast}");

    // An operator sees the subscription, not the administrator's buttons.
    browser.open_with_key(&app, OPERATOR).await;
    browser
        .wait("whoami", "return document.getElementById('who').textContent === 'olga · operator'", 15)
        .await;
    browser.wait("the subscription", &format!("return document.querySelector('{TILE}') !== null"), 15).await;
    let hidden = format!(
        "return [...document.querySelectorAll('{TILE} .webhook-actions, {TILE} button')].every(b => b.offsetParent === null)"
    );
    assert_eq!(browser.js(&hidden).await, json!(true), "no Pause, Resume or Replay for an operator");

    browser.close().await;
    app.stop().await;
}
