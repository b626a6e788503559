//! The dashboard follows the demo store live: jobs submitted over HTTP appear in the job
//! table and run to `completed` on the page, the racks fill, lights and alarms show, an
//! operator pauses a device and cancels a queued job with the page's buttons, and the page
//! reconnects by itself with `since` after its WebSocket closes.

use serde_json::{Value, json};

use super::{Browser, demo_app};
use crate::support::{TestApp, loc};

/// A location in the crane's aisle 2.
fn cloc(row: u16, bay: u16, level: u16, side: u16) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side})
}

/// Submits a job over HTTP and returns its id.
async fn submit(app: &TestApp, body: Value) -> i64 {
    let (status, job) = app.post("/api/v1/jobs", &body).await;
    assert_eq!(status, 201, "{job}");
    job["id"].as_i64().unwrap()
}

/// Waits until the page shows job `id` in `state`.
async fn wait_state(browser: &Browser, id: i64, state: &str, secs: u64) {
    let script = format!(
        "const s = document.querySelector('tr[data-job-id=\"{id}\"] .state'); return s && s.textContent === '{state}';"
    );
    browser.wait(&format!("job {id} to show {state}"), &script, secs).await;
}

/// The script that tells whether a location's position box has a class.
fn has_class(loc_key: &str, class: &str) -> String {
    format!(
        "const p = document.querySelector('.pos[data-loc=\"{loc_key}\"]'); return p && p.classList.contains('{class}');"
    )
}

#[tokio::test]
async fn the_dashboard_follows_the_demo_store_live() {
    let Some(browser) = Browser::start().await else { return };
    let (app, sims) = demo_app(|_| {}).await;
    let crane = &sims.crane;
    browser.open(&app.url("/")).await;

    // The snapshot: connected, both devices online, every location drawn.
    browser.live().await;
    for device in ["shelf1", "crane1", "tower1"] {
        let script = format!(
            "const b = document.querySelector('[data-device=\"{device}\"] .badge.online'); return b && !b.hidden;"
        );
        browser.wait(&format!("{device} to show online"), &script, 15).await;
    }
    let script = "const q = document.querySelector('[data-device=\"tower1\"] tr[data-tag=\"tower.red\"] .tag-quality'); return q && q.textContent === 'good';";
    browser.wait("the light tower's tags", script, 10).await;
    let pause =
        browser.js("return document.querySelector('[data-device=\"tower1\"] button.pause').hidden").await;
    assert_eq!(pause, json!(true), "a tags device takes no jobs, so it has no pause button");
    let cells =
        browser.wait("the racks", "return document.querySelectorAll('.pos[data-loc]').length", 10).await;
    assert_eq!(cells, json!(2 * 10 * 6 * 4 + 2 * 20 * 8 * 2), "every location of both aisles is drawn");

    // Stores to the shelf aisle and the crane aisle, and a light; the barcode is markup on
    // purpose: the page must show it as text.
    let tricky = "<i>BOX-A1</i>";
    let jobs = [
        (submit(&app, json!({"kind": "store", "barcode": tricky, "to": loc(1, 2, 3, 1)})).await, "1-1-2-3-1"),
        (
            submit(&app, json!({"kind": "store", "barcode": "BOX-A2", "to": loc(2, 9, 6, 4)})).await,
            "1-2-9-6-4",
        ),
        (
            submit(&app, json!({"kind": "store", "barcode": "PAL-C1", "to": cloc(1, 4, 3, 1)})).await,
            "2-1-4-3-1",
        ),
        (
            submit(&app, json!({"kind": "store", "barcode": "PAL-C2", "to": cloc(2, 12, 5, 2)})).await,
            "2-2-12-5-2",
        ),
    ];
    let light =
        submit(&app, json!({"kind": "light", "location": loc(1, 2, 3, 1), "color": "red", "on": true})).await;
    for (id, _) in jobs {
        browser
            .wait(
                &format!("job {id} in the table"),
                &format!("return document.querySelector('tr[data-job-id=\"{id}\"]') !== null"),
                10,
            )
            .await;
    }
    for (id, at) in jobs {
        wait_state(&browser, id, "completed", 60).await;
        browser.wait(&format!("{at} to show a box"), &has_class(at, "occ"), 10).await;
    }
    wait_state(&browser, light, "completed", 30).await;
    browser.wait("the red light", &has_class("1-1-2-3-1", "red"), 10).await;

    // A location an operator locks shows it, with the reason in its tooltip.
    let (status, _) = app.post("/api/v1/locations/1/2/5/5/2/lock", &json!({"reason": "box damaged"})).await;
    assert_eq!(status, 200);
    browser.wait("the locked location", &has_class("1-2-5-5-2", "locked"), 10).await;
    let title = browser.js("return document.querySelector('.pos[data-loc=\"1-2-5-5-2\"]').title").await;
    assert!(title.as_str().unwrap().contains("LOCKED by anonymous: box damaged"), "{title}");

    let barcode = browser.text(&format!("tr[data-job-id=\"{}\"] .c-barcode", jobs[0].0)).await;
    assert_eq!(barcode, json!(tricky), "the barcode is shown as text");
    let markup = browser.js("return document.querySelectorAll('#jobs i, .racks i').length").await;
    assert_eq!(markup, json!(0), "no element was made from a barcode");
    let title = browser.js("return document.querySelector('.pos[data-loc=\"1-1-2-3-1\"]').title").await;
    assert!(title.as_str().unwrap().contains(tricky), "the cell's tooltip names the box: {title}");
    let newest = browser.js("return document.querySelector('#jobs tbody tr').dataset.jobId").await;
    assert_eq!(newest, json!(light.to_string()), "newest job first");

    // The crane is drawn in its aisle, where its last job put the pallet.
    browser
        .wait(
            "the crane marker at bay 12",
            "const m = document.querySelector('[data-aisle=\"2\"] .crane-marker'); return m && !m.hidden && m.textContent.includes('bay 12');",
            10,
        )
        .await;

    // An alarm raised and cleared by the crane shows in the list with both times.
    crane.raise_alarm(7011);
    browser.wait("the active alarm", "const a = document.querySelector('#alarms .alarm-item.active'); return a && a.textContent.includes('travel inverter fault');", 10).await;
    browser
        .wait(
            "the alarm on crane1's tile",
            "return !document.querySelector('[data-device=\"crane1\"] .badge.alarm').hidden",
            10,
        )
        .await;
    crane.clear_alarm();
    browser.wait("the alarm cleared", "const a = document.querySelector('#alarms .alarm-item.cleared'); return a && a.textContent.includes('cleared');", 10).await;

    // An operator (no keys: everyone is) pauses the crane from its tile (two clicks): a job
    // for it waits, queued, and is cancelled with its button (two clicks); then the crane
    // is resumed.
    browser.wait("the role", "return window.rackd.who.can('operator')", 10).await;
    let pause = "[data-device=\"crane1\"] button.pause";
    browser.click(pause).await;
    assert_eq!(browser.text(pause).await, json!("Confirm pause"), "the first click only arms the button");
    browser.click(pause).await;
    browser
        .wait(
            "crane1 paused",
            "return !document.querySelector('[data-device=\"crane1\"] .badge.paused').hidden",
            10,
        )
        .await;
    assert_eq!(app.get("/api/v1/devices/crane1").await.1["paused"], json!(true));
    let waiting = submit(&app, json!({"kind": "store", "barcode": "PAL-C3", "to": cloc(1, 7, 8, 1)})).await;
    wait_state(&browser, waiting, "queued", 10).await;
    let cancel = format!("tr[data-job-id=\"{waiting}\"] button.cancel");
    browser.click(&cancel).await;
    assert_eq!(browser.text(&cancel).await, json!("Confirm cancel"), "the first click only arms the button");
    browser.click(&cancel).await;
    wait_state(&browser, waiting, "cancelled", 10).await;
    assert_eq!(app.get(&format!("/api/v1/jobs/{waiting}")).await.1["state"], json!("cancelled"));
    let gone = browser
        .js(&format!("return document.querySelector('{}') === null", cancel.replace('\'', "\\'")))
        .await;
    assert_eq!(gone, json!(true), "an ended job has no cancel button");
    browser.click("[data-device=\"crane1\"] button.resume").await;
    browser.click("[data-device=\"crane1\"] button.resume").await;
    browser
        .wait(
            "crane1 resumed",
            "return document.querySelector('[data-device=\"crane1\"] .badge.paused').hidden",
            10,
        )
        .await;

    // Filters: only cancelled jobs, then all again.
    browser.js("const s = document.getElementById('filter-state'); s.value = 'cancelled'; s.dispatchEvent(new Event('change'));").await;
    let rows =
        browser.js("return [...document.querySelectorAll('#jobs tbody tr')].map(r => r.dataset.jobId)").await;
    assert_eq!(rows, json!([waiting.to_string()]), "the state filter shows only cancelled jobs");
    browser.js("const s = document.getElementById('filter-state'); s.value = ''; s.dispatchEvent(new Event('change'));").await;

    // The WebSocket closes; the page reconnects by itself and catches up with a replay.
    browser.js("window.rackd.live.socket.close();").await;
    let late =
        submit(&app, json!({"kind": "light", "location": loc(1, 5, 1, 2), "color": "green", "on": true}))
            .await;
    wait_state(&browser, late, "completed", 30).await;
    browser.wait("the green light", &has_class("1-1-5-1-2", "green"), 10).await;
    let start = browser
        .wait(
            "the live connection",
            "return document.getElementById('conn').dataset.state === 'live' && window.rackd.live.lastStart",
            15,
        )
        .await;
    assert_eq!(start, json!("replay"), "the reconnect asked for what it missed with since");

    // For the picture: a crane job held mid-way by a hardware alarm (the crane halts until a
    // person resets it) while the shelf stores a box; then the alarm clears and it finishes.
    submit(&app, json!({"kind": "store", "barcode": "BOX-A3", "to": loc(1, 6, 2, 3)})).await;
    let held = submit(&app, json!({"kind": "store", "barcode": "PAL-C4", "to": cloc(2, 17, 7, 1)})).await;
    wait_state(&browser, held, "running", 20).await;
    crane.raise_alarm(7012);
    browser
        .wait(
            "the alarm on the crane's marker",
            "return document.querySelector('[data-aisle=\"2\"] .crane-marker').classList.contains('alarm')",
            10,
        )
        .await;
    // The marker glides to its place (a CSS transition of 0.5 s): the picture waits until no
    // transition runs.
    browser
        .wait(
            "the crane's marker at rest",
            "return !document.getAnimations().some(a => a instanceof CSSTransition && a.playState === 'running')",
            10,
        )
        .await;
    let shot = browser.screenshot("dashboard.png").await;
    eprintln!("dashboard screenshot: {}", shot.display());
    crane.clear_alarm();
    wait_state(&browser, held, "completed", 30).await;

    // A tablet: one column, nothing wider than the screen but the job table (which scrolls).
    browser.client.set_window_size(820, 1180).await.unwrap();
    let wide = browser
        .wait("the narrow layout", "return document.documentElement.scrollWidth <= window.innerWidth", 10)
        .await;
    assert_eq!(wide, json!(true));
    browser.screenshot("dashboard-tablet.png").await;

    // The page keeps at most 500 jobs however long it runs: active ones, then the newest.
    let script = "const done = arguments[arguments.length - 1];
        import('/dashboard/model.js').then(({ Model, MAX_JOBS }) => {
            const m = new Model();
            const t = new Date().toISOString();
            const jobs = [];
            for (let id = 1; id <= 700; id++) jobs.push({ id, kind: 'store', state: id <= 50 ? 'queued' : 'completed', updated_at: t });
            m.addJobs(jobs);
            const ids = [...m.jobs.keys()];
            done({ max: MAX_JOBS, size: m.jobs.size, active: ids.filter((i) => i <= 50).length,
                   oldest_ended: Math.min(...ids.filter((i) => i > 50)) });
        });";
    let kept = browser.client.execute_async(script, vec![]).await.unwrap();
    assert_eq!(kept, json!({"max": 500, "size": 500, "active": 50, "oldest_ended": 251}));

    let toasts = browser.js("return [...document.querySelectorAll('.toast')].map(t => t.textContent)").await;
    assert_eq!(toasts, json!([]), "no error was shown on the page");
    browser.close().await;
    app.stop().await;
}
