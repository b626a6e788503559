//! An operator's buttons, end to end: a crane job failed by a business alarm shows among the
//! jobs that need attention and locks its location; the location is unlocked from its
//! dialog and the job retried from its card, to completion; an aisle is paused and resumed
//! from its summary, and a location locked from its dialog with a reason. Every button asks
//! for a second click.

use serde_json::{Value, json};

use super::{Browser, demo_app};
use crate::support::TestApp;

/// A location in the crane's aisle 2.
fn cloc(row: u16, bay: u16, level: u16, side: u16) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side})
}

/// Clicks a confirming button twice: the first click arms it (its label changes).
async fn confirm(browser: &Browser, css: &str, armed: &str) {
    browser.click(css).await;
    assert_eq!(browser.text(css).await, json!(armed), "the first click only arms {css}");
    browser.click(css).await;
}

/// The lock on a location, as the API says.
async fn lock(app: &TestApp, aisle: u16, row: u16, bay: u16, level: u16, position: u16) -> Value {
    let (_, all) = app.get(&format!("/api/v1/locations?aisle={aisle}")).await;
    let found = all
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["row"] == row && l["bay"] == bay && l["level"] == level && l["position"] == position);
    found.unwrap()["lock"].clone()
}

#[tokio::test]
async fn an_operator_unlocks_retries_pauses_and_locks_from_the_page() {
    let Some(browser) = Browser::start().await else { return };
    let (app, sims) = demo_app(|_| {}).await;
    operator_page(&browser, &app).await;

    // A business alarm (no load at the pick) fails the running job and locks its location.
    let (status, job) =
        app.post("/api/v1/jobs", &json!({"kind": "store", "barcode": "PAL-F", "to": cloc(1, 4, 2, 1)})).await;
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_i64().unwrap();
    browser
        .wait("the job running", &format!("const s = document.querySelector('tr[data-job-id=\"{id}\"] .state'); return s && s.textContent === 'running'"), 20)
        .await;
    sims.crane.raise_alarm(7069);
    let card = format!("#attention .att-item.att-failed[data-job-id=\"{id}\"]");
    browser
        .wait(
            "the failed job among those that need attention",
            &format!("return document.querySelector('{}') !== null", card.replace('\'', "\\'")),
            20,
        )
        .await;
    browser
        .wait(
            "the failed counter",
            "return document.querySelector('[data-counter=\"jobs-failed\"] b').textContent === '1'",
            10,
        )
        .await;
    assert!(lock(&app, 2, 1, 4, 2, 1).await.is_object(), "the location locked itself");

    // The location's dialog: its lock, and Unlock (two clicks) once a person checked it.
    browser.click(".pos[data-loc=\"2-1-4-2-1\"]").await;
    browser.wait("the location's dialog", "return document.getElementById('location-dialog').open", 5).await;
    let facts = browser.text("#location-facts").await;
    assert!(facts.as_str().unwrap().contains("Locked by"), "{facts}");
    confirm(&browser, "#location-actions button.unlock", "Confirm unlock: checked").await;
    browser
        .wait(
            "the location unlocked",
            "return !document.querySelector('.pos[data-loc=\"2-1-4-2-1\"]').classList.contains('locked')",
            10,
        )
        .await;
    assert!(lock(&app, 2, 1, 4, 2, 1).await.is_null(), "unlocked through the API");
    browser.click("#location-actions button[value=\"close\"]").await;

    // Retry from the card: the same job runs again, as its next attempt, to completion.
    confirm(&browser, &format!("{card} button.retry"), "Confirm retry").await;
    browser
        .wait("the retried job to complete", &format!("const s = document.querySelector('tr[data-job-id=\"{id}\"] .state'); return s && s.textContent === 'completed'"), 30)
        .await;
    let (_, job) = app.get(&format!("/api/v1/jobs/{id}")).await;
    assert_eq!((job["state"].clone(), job["attempt"].clone()), (json!("completed"), json!(2)), "{job}");
    browser
        .wait(
            "the card gone",
            &format!("return document.querySelector('{}') === null", card.replace('\'', "\\'")),
            10,
        )
        .await;

    // Pause aisle 1 from its summary, then resume it.
    confirm(&browser, "details.aisle[data-aisle=\"1\"] > summary button.pause", "Confirm pause").await;
    browser
        .wait(
            "aisle 1 paused",
            "return !document.querySelector('details.aisle[data-aisle=\"1\"] .aisle-paused').hidden",
            10,
        )
        .await;
    let (_, aisles) = app.get("/api/v1/aisles").await;
    assert_eq!(aisles[0]["paused"], json!(true), "{aisles}");
    let open = browser.js("return document.querySelector('details.aisle[data-aisle=\"1\"]').open").await;
    assert_eq!(open, json!(true), "a click on the summary's button does not fold the aisle");
    confirm(&browser, "details.aisle[data-aisle=\"1\"] > summary button.resume", "Confirm resume").await;
    browser
        .wait(
            "aisle 1 resumed",
            "return document.querySelector('details.aisle[data-aisle=\"1\"] .aisle-paused').hidden",
            10,
        )
        .await;
    assert_eq!(app.get("/api/v1/aisles").await.1[0]["paused"], json!(false));

    // Lock a location from its dialog, with a reason.
    browser.click(".pos[data-loc=\"1-2-7-4-3\"]").await;
    browser.wait("the location's dialog", "return document.getElementById('location-dialog').open", 5).await;
    browser
        .client
        .find(fantoccini::Locator::Id("location-reason"))
        .await
        .unwrap()
        .send_keys("box crushed")
        .await
        .unwrap();
    confirm(&browser, "#location-actions button.lock", "Confirm lock").await;
    browser
        .wait(
            "the location locked",
            "return document.querySelector('.pos[data-loc=\"1-2-7-4-3\"]').classList.contains('locked')",
            10,
        )
        .await;
    let locked = lock(&app, 1, 2, 7, 4, 3).await;
    assert_eq!(
        (locked["by"].clone(), locked["reason"].clone()),
        (json!("anonymous"), json!("box crushed")),
        "{locked}"
    );

    let toasts = browser.js("return [...document.querySelectorAll('.toast')].map(t => t.textContent)").await;
    assert_eq!(toasts, json!([]), "no error was shown on the page");
    browser.close().await;
    app.stop().await;
}

/// The shelf PLC loses its memory with three stores in its slots: the memory-loss alarm's
/// Unlock and retry shows what it would do (the lost jobs and the locations they locked),
/// changes nothing until the second click on its confirm button, then unlocks and retries
/// exactly those jobs, which run before the retrieves queued behind them.
#[tokio::test]
async fn a_memory_loss_is_unlocked_and_retried_from_its_alarm() {
    let Some(browser) = Browser::start().await else { return };
    let (app, sims) = demo_app(|_| {}).await;
    operator_page(&browser, &app).await;

    // The stores stay in their slots (10 s a task) until the power cycle.
    sims.shelf.set_task_time(std::time::Duration::from_secs(10));
    let place = |bay: u16| json!({"aisle": 1, "row": 1, "bay": bay, "level": 1, "position": 1});
    let stores = (1..=3).map(|b| json!({"kind": "store", "barcode": format!("BOX-{b}"), "to": place(b)}));
    let retrieves = (1..=3).map(|b| json!({"kind": "retrieve", "from": place(b)}));
    let (status, batch) =
        app.post("/api/v1/jobs/batch", &json!({"jobs": stores.chain(retrieves).collect::<Vec<_>>()})).await;
    assert_eq!(status, 201, "{batch}");
    let ids: Vec<i64> = batch["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect();
    let state = async |id: i64| app.get(&format!("/api/v1/jobs/{id}")).await.1["state"].clone();
    crate::support::eventually("the stores in their slots", std::time::Duration::from_secs(10), async || {
        for id in &ids[..3] {
            if state(*id).await == "queued" {
                return false;
            }
        }
        true
    })
    .await;
    sims.shelf.power_cycle();
    sims.shelf.set_task_time(std::time::Duration::from_millis(100));

    browser
        .wait(
            "the memory-loss alarm's button",
            "return document.querySelector('#alarms button.recover') !== null",
            20,
        )
        .await;
    browser.click("#alarms button.recover").await;
    browser
        .wait(
            "the plan",
            "return document.querySelectorAll('#alarms .recovery-jobs li').length === 3 \
             && document.querySelectorAll('#alarms .recovery-locations li').length === 3",
            10,
        )
        .await;
    let check = browser.text("#alarms .recovery-check").await;
    assert!(check.as_str().unwrap().starts_with("Check aisle 1 first"), "{check}");
    for id in &ids[..3] {
        assert_eq!(state(*id).await, "failed", "the plan changed nothing");
    }
    confirm(&browser, "#alarms button.recover-apply", "Confirm: unlock and retry 3").await;
    browser
        .wait(
            "the jobs queued again",
            "const d = document.querySelector('#alarms .recovery-done'); \
             return d !== null && d.textContent === '3 jobs queued again, 3 locations unlocked.'",
            10,
        )
        .await;
    crate::support::eventually("every job completed", std::time::Duration::from_secs(30), async || {
        for id in &ids {
            if state(*id).await != "completed" {
                return false;
            }
        }
        true
    })
    .await;
    assert_eq!(sims.shelf.finished().1, 0, "no retrieve ran before its store");
    let (_, audit) = app.get("/api/v1/audit?limit=6").await;
    let reasons: Vec<&str> =
        audit["entries"].as_array().unwrap().iter().map(|e| e["reason"].as_str().unwrap_or("")).collect();
    assert!(reasons.iter().all(|r| r.contains("after shelf1 lost its memory")), "{audit}");
    let toasts = browser.js("return [...document.querySelectorAll('.toast')].map(t => t.textContent)").await;
    assert_eq!(toasts, json!([]), "no error was shown on the page");
    browser.close().await;
    app.stop().await;
}

/// The dashboard of `app` at 1600x1000, live, its operator's actions offered.
async fn operator_page(browser: &Browser, app: &TestApp) {
    browser.viewport(1600, 1000).await;
    browser.open(&app.url("/")).await;
    browser.live().await;
    browser.wait("the role", "return window.rackd.who.can('operator')", 10).await;
}
