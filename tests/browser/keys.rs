//! With API keys configured, the page asks for a key, refuses a wrong one, and works with a
//! good one given in its address (`/?token=`), which it keeps in local storage.

use fantoccini::Locator;
use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use serde_json::json;

use super::helpers::loc;
use super::{Browser, demo_app};

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

    // The good key in the address: live, and the key leaves the address bar for storage.
    browser.open(&app.url(&format!("/?token={KEY}"))).await;
    browser
        .wait(
            "the connection to be live",
            "return document.getElementById('conn').dataset.state === 'live'",
            15,
        )
        .await;
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
