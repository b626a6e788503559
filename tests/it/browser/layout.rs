//! The control room's first screen, from the page's geometry: with an offline shelf, a
//! crane emergency stop and a queue of jobs, the header counters, the jobs that need
//! attention and the alarms are inside the first viewport at 1600x1000 and 1920x1080 and on
//! a tablet (800x1200, one column, the jobs as cards, no sideways scroll); the crane's
//! label stays inside its aisle and off the bay numbers; aisles fold; the favicon is
//! served. And with the live connection down, the tiles and counters go stale with "as
//! of", and come back with the replay once the server is back.

use rackd::protocols::faults::Faults;
use serde_json::{Value, json};

use super::{Browser, demo_app, demo_app_on, start_again, stop_keeping};
use crate::support::held::HeldPort;
use crate::support::{TestApp, loc};

/// A location in the crane's aisle 2.
fn cloc(row: u16, bay: u16, level: u16, side: u16) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side})
}

async fn submit(app: &TestApp, body: Value) -> i64 {
    let (status, job) = app.post("/api/v1/jobs", &body).await;
    assert_eq!(status, 201, "{job}");
    job["id"].as_i64().unwrap()
}

async fn wait_state(browser: &Browser, id: i64, state: &str, secs: u64) {
    let script = format!(
        "const s = document.querySelector('tr[data-job-id=\"{id}\"] .state'); return s && s.textContent === '{state}';"
    );
    browser.wait(&format!("job {id} to show {state}"), &script, secs).await;
}

/// The number a header counter shows.
async fn counter(browser: &Browser, id: &str) -> String {
    let text = browser.text(&format!("[data-counter=\"{id}\"] b")).await;
    text.as_str().unwrap_or_default().to_owned()
}

/// The first screen's parts: the header, the attention list with its first card, the
/// alarm list with its first alarm.
async fn assert_first_screen(browser: &Browser, size: &str) {
    browser.assert_in_first_screen("#counters", &format!("{size}: the header counters")).await;
    browser.assert_in_first_screen("#attention", &format!("{size}: the attention list")).await;
    browser
        .assert_in_first_screen("#attention .att-item", &format!("{size}: the first job needing attention"))
        .await;
    browser.assert_in_first_screen("#alarms", &format!("{size}: the alarm list")).await;
    browser.assert_in_first_screen("#alarms .alarm-item.active", &format!("{size}: the active alarm")).await;
}

#[tokio::test]
async fn the_first_screen_shows_what_needs_attention() {
    let Some(browser) = Browser::start().await else { return };
    let (app, sims) = demo_app(|_| {}).await;
    browser.viewport(1600, 1000).await;
    browser.open(&app.url("/")).await;
    browser.live().await;

    // The crane runs a job and halts on an emergency stop mid-way: the job needs attention.
    let held = submit(
        &app,
        json!({"kind": "store", "barcode": "PAL-1", "reference": "WMS-PAL-1", "to": cloc(1, 5, 3, 1)}),
    )
    .await;
    // Stopped as soon as the crane moves (its transfer lasts 640 ms: waiting for the page
    // first let a loaded machine finish the job before the alarm).
    crate::support::eventually(
        "the crane to start the job",
        std::time::Duration::from_secs(20),
        async || {
            if sims.crane.action() != 0 { Ok(()) } else { Err("idle") }
        },
    )
    .await;
    sims.crane.raise_alarm(7001);
    wait_state(&browser, held, "running", 20).await;
    browser
        .wait(
            "the held job among those that need attention",
            &format!("const c = document.querySelector('#attention .att-item[data-job-id=\"{held}\"]'); return c && c.textContent.includes('emergency stop');"),
            10,
        )
        .await;

    // The shelf's link goes; then 28 jobs queue behind the shelf and the crane.
    sims.shelf.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
    browser
        .wait("shelf1 offline", "const b = document.querySelector('[data-device=\"shelf1\"] .badge.offline'); return b && !b.hidden", 30)
        .await;
    for i in 0..14u16 {
        submit(&app, json!({"kind": "store", "reference": format!("WMS-S{i}"), "barcode": format!("BOX-{i}"), "to": loc(1 + i % 2, 1 + i % 10, 1 + i / 10, 1)})).await;
        submit(&app, json!({"kind": "store", "reference": format!("WMS-C{i}"), "barcode": format!("PAL-C{i}"), "to": cloc(2, 1 + i, 2, 1)})).await;
    }
    browser.wait("28 jobs queued in the header", "const b = document.querySelector('[data-counter=\"jobs-queued\"] b'); return b && b.textContent === '28'", 15).await;
    assert_eq!(
        counter(&browser, "alarms-hardware").await,
        "1",
        "the emergency stop counts as a hardware alarm"
    );
    assert_eq!(counter(&browser, "devices-offline").await, "1", "the shelf counts as offline");
    assert_eq!(counter(&browser, "jobs-running").await, "1");
    let bad = browser
        .js("return document.querySelector('[data-counter=\"alarms-hardware\"]').classList.contains('bad')")
        .await;
    assert_eq!(bad, json!(true), "a hardware alarm stands out in the header");

    // 1600x1000: the counters, the attention list and the alarms without scrolling.
    assert_first_screen(&browser, "1600x1000").await;
    browser.screenshot_viewport("first-screen-1600x1000.png").await;
    browser.viewport(1920, 1080).await;
    assert_first_screen(&browser, "1920x1080").await;
    browser.screenshot_viewport("first-screen-1920x1080.png").await;

    // An aisle folds behind its summary, which says what matters about it.
    let (status, _) =
        app.post("/api/v1/locations/2/1/20/8/2/lock", &json!({"reason": "pallet overhangs"})).await;
    assert_eq!(status, 200);
    browser
        .wait(
            "aisle 2's summary",
            "const s = document.querySelector('details.aisle[data-aisle=\"2\"] > summary'); return s && s.textContent.includes('1 locked') && s.textContent.includes('occupied') && s.textContent.includes('alarm 7001');",
            10,
        )
        .await;
    let height =
        "return document.querySelector('details.aisle[data-aisle=\"1\"]').getBoundingClientRect().height";
    let open = browser.js(height).await.as_f64().unwrap();
    browser.click("details.aisle[data-aisle=\"1\"] > summary").await;
    let folded = browser
        .js("const d = document.querySelector('details.aisle[data-aisle=\"1\"]'); return [d.open, d.querySelector('.aisle-block').checkVisibility()];")
        .await;
    assert_eq!(folded, json!([false, false]), "aisle 1 folded away");
    let closed = browser.js(height).await.as_f64().unwrap();
    assert!(closed < open / 4.0, "a folded aisle is its summary line: {closed} of {open} px");
    browser.click("details.aisle[data-aisle=\"1\"] > summary").await;

    // The crane label at bay 19 (of 20) stays inside the aisle and off the bay numbers.
    sims.crane.clear_alarm();
    wait_state(&browser, held, "completed", 30).await;
    sims.shelf.set_faults(Faults::default());
    let far = submit(&app, json!({"kind": "store", "barcode": "PAL-FAR", "to": cloc(1, 19, 4, 1)})).await;
    wait_state(&browser, far, "completed", 60).await;
    browser.viewport(1600, 1000).await;
    browser
        .wait(
            "the crane marker at bay 19, at rest",
            "const m = document.querySelector('[data-aisle=\"2\"] .crane-marker');
             return m && !m.hidden && m.textContent.includes('bay 19')
                 && !document.getAnimations().some(a => a instanceof CSSTransition && a.playState === 'running');",
            20,
        )
        .await;
    let script = "const a = document.querySelector('[data-aisle=\"2\"]');
        const m = a.querySelector('.crane-marker').getBoundingClientRect();
        const block = a.querySelector('.aisle-block').getBoundingClientRect();
        const covered = [...a.querySelectorAll('.lbl.bay')].map(n => n.getBoundingClientRect())
            .filter(b => b.left < m.right && m.left < b.right && b.top < m.bottom && m.top < b.bottom).length;
        const bay19 = a.querySelectorAll('.lbl.bay')[18].getBoundingClientRect();
        return {inside: m.left >= block.left && m.right <= block.right + 0.5, covered,
                over19: m.left <= bay19.right && m.right >= bay19.left};";
    let marker = browser.js(script).await;
    assert_eq!(marker, json!({"inside": true, "covered": 0, "over19": true}), "the crane's label at bay 19");
    // Also when the page never saw the crane at the put: it draws once per frame from the
    // newest status, and a loaded machine can skip the whole put (the crane goes from
    // travelling there to idle, its job completed).
    let script = "const done = arguments[arguments.length - 1];
        Promise.all([import('/dashboard/model.js'), import('/dashboard/crane.js')]).then(([{ Model }, { Cranes }]) => {
            const model = new Model();
            const cranes = new Cranes(model);
            const div = () => document.createElement('div');
            const lane = {marker: div(), track: div(), mast: div(), info: div(), bays: 20};
            lane.marker.append(document.createElement('span'));
            const to = {aisle: 2, row: 1, bay: 19, level: 4, position: 1};
            const job = (seq, state) => model.applyEvent({seq, type: 'job.updated', data: {id: 1, kind: 'store', device: 'c1', state, to, updated_at: new Date(seq * 1000).toISOString()}});
            const crane = (action_state, task, travel) => ({id: 'c1', online: true, crane: {action_state, action: '', task, travel_position: travel, lift_position: travel / 10, load: false}});
            const seen = [];
            job(1, 'running');
            for (const state of [2, 5, 12]) {
                cranes.draw(lane, crane(state, 1, 0));
                seen.push(lane.marker.textContent);
            }
            job(2, 'completed');
            cranes.draw(lane, crane(0, 0, 19000));
            seen.push(lane.marker.textContent);
            done(seen);
        });";
    let seen = browser.client.execute_async(script, vec![]).await.unwrap();
    assert_eq!(
        seen,
        json!(["c1 · P&D", "c1 · P&D", "c1 · P&D → bay 19 L4", "c1 · bay 19 L4"]),
        "an idle crane is drawn where its completed job put the load"
    );
    browser
        .js("document.querySelector('[data-aisle=\"2\"] .lane-wrap').scrollIntoView({block: 'center'})")
        .await;
    browser.screenshot_viewport("crane-bay-19.png").await;

    // The favicon is served (browsers ask for /favicon.ico whatever the page says).
    for path in ["/favicon.ico", "/favicon.svg"] {
        let response = app.client.get(app.url(path)).send().await.unwrap();
        assert_eq!(response.status(), 200, "{path}");
        assert_eq!(response.headers()["content-type"], "image/svg+xml", "{path}");
    }

    // A tablet: one column, the first screen still holds the attention list and the alarms,
    // the jobs are cards with their reference, and nothing scrolls sideways. Again a crane
    // job held by an emergency stop.
    let held = submit(&app, json!({"kind": "store", "barcode": "PAL-2", "to": cloc(2, 16, 3, 1)})).await;
    // Stopped as soon as the crane moves (its transfer lasts 640 ms: waiting for the page
    // first let a loaded machine finish the job before the alarm).
    crate::support::eventually(
        "the crane to start the job",
        std::time::Duration::from_secs(20),
        async || {
            if sims.crane.action() != 0 { Ok(()) } else { Err("idle") }
        },
    )
    .await;
    sims.crane.raise_alarm(7001);
    wait_state(&browser, held, "running", 20).await;
    browser.viewport(800, 1200).await;
    browser
        .wait("the active alarm", "return document.querySelector('#alarms .alarm-item.active') !== null", 10)
        .await;
    browser
        .wait(
            "a card among those that need attention",
            "return document.querySelector('#attention .att-item') !== null",
            10,
        )
        .await;
    assert_first_screen(&browser, "800x1200").await;
    let script = "const x = (s) => Math.round(document.querySelector(s).getBoundingClientRect().left);
        const tiles = [...document.querySelectorAll('[data-device]')].map(t => Math.round(t.getBoundingClientRect().left));
        return {panels: new Set([x('.attention-panel'), x('.alarms-panel'), x('.devices-panel'), x('.store'), x('.jobs-panel')]).size,
                tiles: new Set(tiles).size};";
    assert_eq!(browser.js(script).await, json!({"panels": 1, "tiles": 1}), "one column on a tablet");
    let card = browser
        .js("const r = document.querySelector('#jobs tbody tr[data-job-id]');
             const ref = [...document.querySelectorAll('#jobs td.c-reference')].find(td => td.textContent === 'WMS-C13');
             return {display: getComputedStyle(r).display, reference: ref ? ref.getBoundingClientRect().width > 0 : null};")
        .await;
    assert_eq!(
        card,
        json!({"display": "grid", "reference": true}),
        "jobs as cards, with the reference shown"
    );
    let wide = browser.js("return document.documentElement.scrollWidth <= window.innerWidth").await;
    assert_eq!(wide, json!(true), "no sideways scroll on a tablet");
    browser.screenshot_viewport("first-screen-800x1200.png").await;
    sims.crane.clear_alarm();
    wait_state(&browser, held, "completed", 30).await;

    let toasts = browser.js("return [...document.querySelectorAll('.toast')].map(t => t.textContent)").await;
    assert_eq!(toasts, json!([]), "no error was shown on the page");
    browser.close().await;
    app.stop().await;
}

#[tokio::test]
async fn tiles_go_stale_when_the_live_connection_drops() {
    let Some(browser) = Browser::start().await else { return };
    // The port is held while the server is down, for it to come back where the page is.
    let port = HeldPort::new();
    let (app, sims) = demo_app_on(Some(&port), |_| {}).await;
    browser.viewport(1600, 1000).await;
    browser.open(&app.url("/")).await;
    browser.live().await;
    browser.wait("the devices", "return document.querySelectorAll('[data-device]').length === 3", 10).await;
    let fresh = browser
        .js("return [document.body.classList.contains('stale'), getComputedStyle(document.querySelector('[data-device] .as-of')).display]")
        .await;
    assert_eq!(fresh, json!([false, "none"]), "live: nothing says stale");

    // The server goes away (stopped in the background: a graceful stop may wait for the
    // page's socket): every tile and the counters grey out and say since when.
    let stopping = tokio::spawn(stop_keeping(app));
    browser
        .wait(
            "the page to go stale",
            "return document.body.classList.contains('stale') && document.getElementById('conn').dataset.state !== 'live'",
            20,
        )
        .await;
    let script = "const tiles = [...document.querySelectorAll('[data-device]')];
        const asOf = tiles.map(t => t.querySelector('.as-of'));
        return {tiles: tiles.length,
                shown: asOf.filter(a => getComputedStyle(a).display !== 'none' && /^as of \\d\\d:\\d\\d:\\d\\d$/.test(a.textContent)).length,
                grey: tiles.filter(t => getComputedStyle(t).filter.includes('grayscale')).length,
                counters: getComputedStyle(document.getElementById('counters')).filter.includes('grayscale'),
                header: /^as of \\d\\d:\\d\\d:\\d\\d$/.test(document.getElementById('as-of').textContent)};";
    let stale = browser.js(script).await;
    assert_eq!(
        stale,
        json!({"tiles": 3, "shown": 3, "grey": 3, "counters": true, "header": true}),
        "stale tiles and counters"
    );
    browser.screenshot_viewport("dashboard-stale.png").await;
    let (app, _dir) = start_again(stopping.await.unwrap(), &port, &sims).await;

    // Back: the page reconnects by itself, asks for what it missed, and is live again.
    let start = browser
        .wait(
            "the page to be live again",
            "return document.getElementById('conn').dataset.state === 'live' && !document.body.classList.contains('stale') && window.rackd.live.lastStart",
            30,
        )
        .await;
    assert_eq!(start, json!("replay"), "back with the replay of what was missed");
    let grey = browser
        .js("return [...document.querySelectorAll('[data-device]')].filter(t => getComputedStyle(t).filter.includes('grayscale')).length")
        .await;
    assert_eq!(grey, json!(0), "no tile stays grey");
    let id =
        submit(&app, json!({"kind": "light", "location": loc(1, 1, 1, 1), "color": "green", "on": true}))
            .await;
    wait_state(&browser, id, "completed", 30).await;

    browser.close().await;
    app.stop().await;
}
