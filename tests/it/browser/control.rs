//! What the page shows of issue 14's API: why jobs wait (an offline device, a paused
//! device, a locked location, a crane alarm), the KPIs drawn from `GET /api/v1/stats`,
//! acknowledging an alarm, and the key's name and role from `GET /api/v1/whoami`. These
//! pass once rackd serves that API; the page's side is here.

use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::protocols::faults::Faults;
use serde_json::{Value, json};

use super::{Browser, demo_app};
use crate::support::{TestApp, loc};

fn cloc(row: u16, bay: u16, level: u16, side: u16) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side})
}

async fn submit(app: &TestApp, body: Value) -> i64 {
    let (status, job) = app.post("/api/v1/jobs", &body).await;
    assert_eq!(status, 201, "{job}");
    job["id"].as_i64().unwrap()
}

/// Waits until job `id` is in the attention list for `reason`, with its reason in words
/// both there and in the job table; returns the card's text.
async fn wait_reason(browser: &Browser, id: i64, reason: &str) -> String {
    let script = format!(
        "const c = document.querySelector('#attention .att-item[data-job-id=\"{id}\"][data-reason=\"{reason}\"]');
         const d = document.querySelector('tr[data-job-id=\"{id}\"] td.c-detail.reason-{reason}');
         return c && d && d.textContent.length > 0 && c.querySelector('.att-why').textContent;"
    );
    let text = browser.wait(&format!("job {id} waiting: {reason}"), &script, 20).await;
    text.as_str().unwrap().to_owned()
}

#[tokio::test]
async fn the_page_says_why_each_job_waits() {
    let Some(browser) = Browser::start().await else { return };
    let (app, sims) = demo_app(|_| {}).await;
    browser.viewport(1600, 1000).await;
    browser.open(&app.url("/")).await;
    browser.live().await;

    // A locked location: the job on it waits, naming who locked it.
    let (status, _) = app.post("/api/v1/locations/1/1/2/3/1/lock", &json!({"reason": "box damaged"})).await;
    assert_eq!(status, 200);
    let locked = submit(&app, json!({"kind": "store", "barcode": "BOX-L", "to": loc(1, 2, 3, 1)})).await;
    let text = wait_reason(&browser, locked, "location_locked").await;
    assert!(!text.is_empty());
    let by = browser.js(&format!("return window.rackd.model.jobs.get({locked}).waiting.by")).await;
    assert_eq!(by, json!("anonymous"), "the person who locked it");
    assert_eq!(browser.text("#attention-reasons [data-reason=\"location_locked\"] b").await, json!("1"));

    // A paused device: the crane's job waits until it is resumed.
    let (status, _) = app.post("/api/v1/devices/crane1/pause", &json!({"reason": "inspection"})).await;
    assert_eq!(status, 200);
    let paused = submit(&app, json!({"kind": "store", "barcode": "PAL-P", "to": cloc(1, 3, 3, 1)})).await;
    wait_reason(&browser, paused, "device_paused").await;
    let (status, _) = app.post("/api/v1/devices/crane1/resume", &json!({})).await;
    assert_eq!(status, 200);
    browser
        .wait(
            "the resumed job to leave the attention list",
            &format!(
                "return document.querySelector('#attention .att-item[data-job-id=\"{paused}\"]') === null"
            ),
            30,
        )
        .await;

    // A crane alarm: a new job for it waits, with the alarm's code.
    sims.crane.raise_alarm(7001);
    browser
        .wait("the crane's alarm", "return document.querySelector('#alarms .alarm-item.active') !== null", 10)
        .await;
    let alarmed = submit(&app, json!({"kind": "store", "barcode": "PAL-A", "to": cloc(1, 6, 3, 1)})).await;
    wait_reason(&browser, alarmed, "device_alarm").await;
    let code = browser.js(&format!("return window.rackd.model.jobs.get({alarmed}).waiting.code")).await;
    assert_eq!(code, json!(7001));

    // An offline device: the shelf's link goes, and its new job waits for it.
    sims.shelf.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
    browser
        .wait("shelf1 offline", "const b = document.querySelector('[data-device=\"shelf1\"] .badge.offline'); return b && !b.hidden", 30)
        .await;
    let offline = submit(&app, json!({"kind": "store", "barcode": "BOX-O", "to": loc(2, 4, 1, 1)})).await;
    wait_reason(&browser, offline, "device_offline").await;

    // The table filters by reason.
    browser.js("const s = document.getElementById('filter-waiting'); s.value = 'device_offline'; s.dispatchEvent(new Event('change'));").await;
    let script = "return [...document.querySelectorAll('#jobs tbody tr')]
        .map(r => [Number(r.dataset.jobId), r.querySelector('td.c-detail').classList.contains('reason-device_offline')])";
    let rows = browser.js(script).await;
    let rows = rows.as_array().unwrap();
    assert!(rows.contains(&json!([offline, true])), "the waiting filter shows the job: {rows:?}");
    assert!(rows.iter().all(|r| r[1] == json!(true)), "and only jobs waiting for that: {rows:?}");
    browser.js("const s = document.getElementById('filter-waiting'); s.value = ''; s.dispatchEvent(new Event('change'));").await;
    browser.assert_in_first_screen("#attention", "the attention list").await;
    browser.screenshot_viewport("dashboard-waiting.png").await;

    sims.shelf.set_faults(Faults::default());
    sims.crane.clear_alarm();
    browser.close().await;
    app.stop().await;
}

const OPERATOR: &str = "rk_browser-alice";

#[tokio::test]
async fn kpis_acknowledgement_and_whoami() {
    let Some(browser) = Browser::start().await else { return };
    let (app, sims) = demo_app(|c| {
        c.auth.keys =
            vec![KeyConfig { name: "alice".into(), role: Role::Operator, hash: KeyHash::of(OPERATOR) }];
    })
    .await;
    browser.viewport(1600, 1000).await;
    browser.open_with_key(&app, OPERATOR).await;
    browser.live().await;
    browser
        .wait("whoami", "return document.getElementById('who').textContent === 'alice · operator'", 10)
        .await;

    // Jobs run, and the KPI panel draws them per device (read again on a new period).
    let post = |body: Value| {
        let request = app.client.post(app.url("/api/v1/jobs")).bearer_auth(OPERATOR).json(&body);
        async move {
            let response = request.send().await.unwrap();
            assert_eq!(response.status(), 201);
        }
    };
    for i in 0..3u16 {
        post(json!({"kind": "store", "barcode": format!("BOX-K{i}"), "to": loc(1, 1 + i, 1, 1)})).await;
    }
    let script = "return window.rackd.model.jobs.size === 3 && [...window.rackd.model.jobs.values()].every(j => j.state === 'completed')";
    browser.wait("the jobs to complete", script, 30).await;
    browser.click("#kpi-shift").await;
    browser.click("#kpi-hour").await;
    let script = "const c = document.querySelector('[data-kpi-device=\"shelf1\"]');
        return c && !document.getElementById('kpi-panel').hidden && c.querySelectorAll('svg.chart').length >= 2
            && c.querySelector('.kpi-completed b').textContent;";
    let completed = browser.wait("shelf1's KPIs with their charts", script, 20).await;
    assert_eq!(completed, json!("3"), "three jobs completed in the last hour");

    // An alarm: its plain text, what to do, and Acknowledge, which records alice.
    sims.crane.raise_alarm(7001);
    let button = "#alarms .alarm-item.active button.ack";
    browser
        .wait(
            "the Acknowledge button",
            &format!("const b = document.querySelector('{button}'); return b && b.offsetParent !== null"),
            10,
        )
        .await;
    let action = browser.text("#alarms .alarm-item.active .alarm-action").await;
    assert!(action.as_str().is_some_and(|a| !a.is_empty()), "an emergency stop says what to do: {action}");
    browser.click(button).await;
    browser
        .wait(
            "the acknowledgement",
            "const a = document.querySelector('#alarms .alarm-item.active .alarm-ack'); return a && a.textContent.startsWith('acknowledged by alice')",
            10,
        )
        .await;
    let alarms = app.client.get(app.url("/api/v1/alarms")).bearer_auth(OPERATOR).send().await.unwrap();
    let alarms: Value = alarms.json().await.unwrap();
    assert_eq!(alarms["alarms"][0]["acknowledged_by"], json!("alice"));
    let export = browser.js("return !document.getElementById('alarm-export').hidden").await;
    assert_eq!(export, json!(true), "the CSV export is offered");
    browser.screenshot_viewport("dashboard-kpi.png").await;

    sims.crane.clear_alarm();
    browser.close().await;
    app.stop().await;
}
