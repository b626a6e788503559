//! With API keys configured, the page asks for a key, refuses a wrong one, and works with a
//! good one given in its address (`/?token=`) once the operator accepts it (the page names
//! whose key it is first; ignored, it is not kept), keeping it in local storage; a viewer's
//! key shows no button a viewer may not use, an operator's shows them.

use fantoccini::Locator;
use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use serde_json::{Value, json};

use super::{Browser, demo_app};
use crate::support::loc;

const KEY: &str = "rk_browser-test-operator";

#[tokio::test]
async fn with_keys_the_page_asks_for_one_and_works_once_given() {
    let Some(browser) = Browser::start().await else { return };
    let (app, _sims) = demo_app(|c| {
        c.auth.keys =
            vec![KeyConfig { name: "operator".into(), role: Role::Operator, hash: KeyHash::of(KEY) }];
    })
    .await;

    // No key: the page asks for one and says so in its connection indicator.
    browser.open(&app.url("/")).await;
    browser.wait("the key dialog", "return document.getElementById('key-dialog').open", 15).await;
    browser
        .wait(
            "the indicator to ask for a key",
            "return document.getElementById('conn').dataset.state === 'key'",
            10,
        )
        .await;
    let devices = browser.js("return document.querySelectorAll('[data-device]').length").await;
    assert_eq!(devices, json!(0), "nothing is shown without a key");
    browser.screenshot("dashboard-key.png").await;

    // A wrong key typed into the dialog is refused, and the page asks again.
    let input = browser.client.find(Locator::Id("key-input")).await.unwrap();
    input.send_keys("rk_wrong").await.unwrap();
    browser.click("#key-save").await;
    browser
        .wait(
            "the dialog to ask again",
            "const d = document.getElementById('key-dialog'); return d.open && document.getElementById('key-message').textContent.includes('not accepted');",
            15,
        )
        .await;

    // A key in a link is taken out of the address bar at once, and the page asks first,
    // naming whose key it is. Ignored, it is not kept.
    browser.open(&app.url(&format!("/?token={KEY}"))).await;
    let asked = "const t = document.getElementById('token-who').textContent;
        return document.getElementById('token-dialog').open && t.startsWith('It is the key') && t";
    let who = browser.wait("the page to ask about the link's key, naming it", asked, 10).await;
    assert_eq!(who, json!("It is the key “operator” (operator)."));
    let url = browser.client.current_url().await.unwrap();
    assert!(!url.as_str().contains("token"), "the key left the address before any answer: {url}");
    let stored = "return localStorage.getItem('rackd.key')";
    assert_eq!(browser.js(stored).await, json!("rk_wrong"), "the page's own key is kept until the answer");
    browser.click("#token-ignore").await;
    browser
        .wait(
            "the key dialog again, the link's key ignored",
            "return document.getElementById('key-dialog').open",
            10,
        )
        .await;
    assert_eq!(browser.js(stored).await, json!("rk_wrong"), "ignored: the link's key is not kept");

    // Accepted: live, and the key is kept.
    browser.open_with_key(&app, KEY).await;
    browser.live().await;
    browser.wait("the devices", "return document.querySelectorAll('[data-device]').length === 3", 10).await;
    let open = browser.js("return document.getElementById('key-dialog').open").await;
    assert_eq!(open, json!(false), "no dialog once the key is good");
    let url = browser.client.current_url().await.unwrap();
    assert!(!url.as_str().contains("token"), "the key is taken out of the address: {url}");
    assert_eq!(browser.js("return localStorage.getItem('rackd.key')").await, json!(KEY));

    // It works: a job submitted with the key runs to completion on the page.
    let response = app
        .client
        .post(app.url("/api/v1/jobs"))
        .bearer_auth(KEY)
        .json(&json!({"kind": "store", "barcode": "KEYED-1", "to": loc(1, 1, 1, 1)}))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), 201);
    let id = response.json::<serde_json::Value>().await.unwrap()["id"].as_i64().unwrap();
    let done = format!(
        "const s = document.querySelector('tr[data-job-id=\"{id}\"] .state'); return s && s.textContent === 'completed';"
    );
    browser.wait("the job to complete on the page", &done, 30).await;

    // A reload without the token still works: the key was kept.
    browser.open(&app.url("/")).await;
    browser
        .wait(
            "the connection to be live again",
            "return document.getElementById('conn').dataset.state === 'live'",
            15,
        )
        .await;
    browser.wait("the finished job from history", &done, 10).await;

    browser.close().await;
    app.stop().await;
}

const VIEWER: &str = "rk_browser-test-viewer";

/// The action buttons the page shows now: visible elements of class `op` and buttons
/// that change something, by their classes.
const VISIBLE_ACTIONS: &str = "return [...document.querySelectorAll('.op, button.cancel, button.retry, button.pause, button.resume, button.ack, button.lock, button.unlock')]
    .filter(n => n.getClientRects().length > 0).map(n => n.textContent);";

#[tokio::test]
async fn a_viewer_sees_no_buttons_it_cannot_use() {
    let Some(browser) = Browser::start().await else { return };
    let (app, _sims) = demo_app(|c| {
        c.auth.keys = vec![
            KeyConfig { name: "operator".into(), role: Role::Operator, hash: KeyHash::of(KEY) },
            KeyConfig { name: "viewer".into(), role: Role::Viewer, hash: KeyHash::of(VIEWER) },
        ];
    })
    .await;
    // Something for every button: a paused crane with a queued job, a locked location.
    let post = |path: &str, body: Value| {
        let request = app.client.post(app.url(path)).bearer_auth(KEY).json(&body);
        async move { request.send().await.unwrap().status().as_u16() }
    };
    assert_eq!(post("/api/v1/devices/crane1/pause", json!({})).await, 200);
    let job = json!({"kind": "store", "barcode": "PAL-V", "to": {"aisle": 2, "row": 1, "bay": 3, "level": 2, "position": 1}});
    assert_eq!(post("/api/v1/jobs", job).await, 201);
    assert_eq!(post("/api/v1/locations/1/1/2/3/1/lock", json!({"reason": "checking"})).await, 200);

    // The viewer: everything shown, no button that would be refused.
    browser.open_with_key(&app, VIEWER).await;
    browser.live().await;
    browser.wait("the role", "return window.rackd.who.role === 'viewer'", 10).await;
    browser
        .wait("the queued job", "return document.querySelector('#jobs tbody tr[data-job-id]') !== null", 10)
        .await;
    browser
        .wait(
            "crane1 paused",
            "return !document.querySelector('[data-device=\"crane1\"] .badge.paused').hidden",
            10,
        )
        .await;
    assert_eq!(browser.js(VISIBLE_ACTIONS).await, json!([]), "a viewer sees no action button");
    browser.click(".pos[data-loc=\"1-1-2-3-1\"]").await;
    browser.wait("the location's dialog", "return document.getElementById('location-dialog').open", 5).await;
    let dialog = browser.js("return document.getElementById('location-facts').textContent").await;
    assert!(dialog.as_str().unwrap().contains("Locked by operator: checking"), "{dialog}");
    assert_eq!(browser.js(VISIBLE_ACTIONS).await, json!([]), "nor in the location's dialog");
    browser.screenshot_viewport("dashboard-viewer.png").await;

    // The operator, on the same page: Cancel, Resume, Pause aisle, Unlock.
    browser.open_with_key(&app, KEY).await;
    browser.live().await;
    browser.wait("the role", "return window.rackd.who.role === 'operator'", 10).await;
    browser
        .wait("the queued job", "return document.querySelector('#jobs tbody tr[data-job-id]') !== null", 10)
        .await;
    let shown = browser
        .wait(
            "the operator's buttons",
            &format!("const b = (() => {{ {VISIBLE_ACTIONS} }})(); return b.length > 0 && b"),
            10,
        )
        .await;
    for label in ["Cancel", "Resume", "Pause aisle"] {
        assert!(shown.as_array().unwrap().contains(&json!(label)), "an operator sees {label}: {shown}");
    }
    browser.click(".pos[data-loc=\"1-1-2-3-1\"]").await;
    browser.wait("the Unlock button", "const b = document.querySelector('#location-actions button.unlock'); return b && b.offsetParent !== null", 5).await;

    browser.close().await;
    app.stop().await;
}
