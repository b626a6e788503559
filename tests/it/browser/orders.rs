//! Orders on the page (issue 52): a sequence its machine holds shows in the Sequences panel
//! with its members as chips, the position due and why it waits, and moves on when the due
//! member is passed; a sequence missing its first position and a job waiting for another
//! show the `sequence` and `dependency` reasons; jobs past their deadline carry a late badge
//! that grows by the page's clock, and count in the header. On a tablet the panel fits the
//! screen.

use serde_json::{Value, json};
use time::format_description::well_known::Rfc3339;

use super::{Browser, demo_app};
use crate::support::{TestApp, loc};

/// A location in the crane's aisle 2.
fn cloc(row: u16, bay: u16, level: u16, side: u16) -> Value {
    json!({"aisle": 2, "row": row, "bay": bay, "level": level, "position": side})
}

/// A deadline `secs` seconds ago, as RFC 3339.
fn ago(secs: i64) -> String {
    (time::OffsetDateTime::now_utc() - time::Duration::seconds(secs)).format(&Rfc3339).unwrap()
}

/// Posts `jobs` as one batch and returns their ids, in order.
async fn batch(app: &TestApp, jobs: Vec<Value>) -> Vec<i64> {
    let (status, posted) = app.post("/api/v1/jobs/batch", &json!({ "jobs": jobs })).await;
    assert_eq!(status, 201, "{posted}");
    posted["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect()
}

/// Waits until the panel shows sequence `name` with these chips (`position:status ...`),
/// this position due and its reason containing `why`; returns the reason's text.
async fn wait_sequence(browser: &Browser, name: &str, chips: &str, due: u32, why: &str) -> String {
    let script = format!(
        "const l = document.querySelector('#sequences .seq[data-sequence=\"{name}\"]');
         if (!l || document.getElementById('sequences-panel').hidden) return false;
         const chips = [...l.querySelectorAll('.seq-chips .seq-pos')].map((c) => `${{c.dataset.position}}:${{c.dataset.status}}`);
         const w = l.querySelector('.seq-why').textContent;
         return chips.join(' ') === '{chips}' && l.querySelector('.seq-next').textContent === 'due {due}'
             && w.includes('{why}') && w;"
    );
    let what = format!("sequence {name} as {chips}, due {due}, waiting: {why}");
    browser.wait(&what, &script, 30).await.as_str().unwrap().to_owned()
}

/// The seconds a late badge says (`late by 104 s`), or None.
fn late_secs(text: &Value) -> Option<i64> {
    text.as_str()?.strip_prefix("late by ")?.strip_suffix(" s")?.parse().ok()
}

#[tokio::test]
async fn the_page_shows_sequences_and_late_jobs() {
    let Some(browser) = Browser::start().await else { return };
    let (app, _sims) = demo_app(|_| {}).await;
    browser.viewport(1600, 1000).await;
    browser.open(&app.url("/")).await;
    browser.live().await;
    let hidden = browser.js("return document.getElementById('sequences-panel').hidden").await;
    assert_eq!(hidden, json!(true), "no sequence under way: no panel");

    // The crane is paused, so it holds what it is given: a sequence of three retrieves,
    // ten minutes past their deadline, and a store 30 s past its own.
    let (status, _) = app.post("/api/v1/devices/crane1/pause", &json!({"reason": "inspection"})).await;
    assert_eq!(status, 200);
    let ten_min = ago(600);
    let members = (1..=3u16).map(|p| {
        json!({"kind": "retrieve", "reference": format!("SO-52-{p}"), "from": cloc(1, 2 * p, 3, 1),
            "sequence": {"name": "SO-52", "position": p, "last": p == 3}, "deadline": ten_min})
    });
    let mut jobs: Vec<Value> = members.collect();
    jobs.push(json!({"kind": "store", "reference": "LATE-1", "barcode": "PAL-L", "to": cloc(2, 9, 2, 1), "deadline": ago(30)}));
    let ids = batch(&app, jobs).await;
    let late = ids[3];

    let why = wait_sequence(&browser, "SO-52", "1:due 2:waiting 3:waiting", 1, "paused").await;
    assert!(why.contains("crane1"), "the due member's reason names its device: {why}");
    let badge =
        browser.wait("the sequence's late badge", "const b = document.querySelector('#sequences .seq[data-sequence=\"SO-52\"] .late'); return b && !b.hidden && b.textContent", 10).await;
    // Ten minutes and however long a busy machine took to get here.
    let minutes =
        badge.as_str().and_then(|b| b.strip_prefix("late by ")?.strip_suffix(" min")?.parse::<u32>().ok());
    assert!(matches!(minutes, Some(10..=12)), "the sequence is as late as its latest member: {badge}");
    browser
        .wait(
            "four late jobs in the header",
            "const c = document.querySelector('[data-counter=\"jobs-late\"]'); return c.querySelector('b').textContent === '4' && c.classList.contains('bad')",
            10,
        )
        .await;
    browser.assert_in_first_screen("[data-counter=\"jobs-late\"]", "1600x1000: the late counter").await;

    // The store's badge, in the job table and on its card, grows by the page's clock: the
    // server's `late_by_s` changes only with the job's events, and a queued job on a paused
    // crane has none.
    let row_badge = format!("tr[data-job-id=\"{late}\"] td.c-state .late");
    let first = browser
        .wait(
            "the store's late badge",
            &format!(
                "const b = document.querySelector('{row_badge}'); return b && !b.hidden && b.textContent"
            ),
            10,
        )
        .await;
    let first = late_secs(&first).unwrap_or_else(|| panic!("a late badge in seconds: {first}"));
    assert!((30..120).contains(&first), "late by 30 s and a little: {first}");
    let grown = browser
        .wait(
            "the store's badge to grow without an event",
            &format!(
                "const b = document.querySelector('{row_badge}').textContent;
                 const told = window.rackd.model.jobs.get({late}).late_by_s;
                 const s = Number(b.replace('late by ', '').replace(' s', ''));
                 return s >= {first} + 2 && s > (told || 0) + 1 && s;"
            ),
            20,
        )
        .await;
    assert!(grown.as_i64().unwrap() > first, "{grown}");
    let card = browser
        .wait(
            "the store's card with its late badge",
            &format!("const b = document.querySelector('#attention .att-item[data-job-id=\"{late}\"] .late'); return b && !b.hidden && b.textContent"),
            10,
        )
        .await;
    assert!(late_secs(&card).is_some(), "{card}");

    // Position 1 is cancelled alone: it is passed, and position 2 is due.
    let (status, cancelled) = app.post(&format!("/api/v1/jobs/{}/cancel", ids[0]), &json!({})).await;
    assert_eq!(status, 200, "{cancelled}");
    wait_sequence(&browser, "SO-52", "1:passed 2:due 3:waiting", 2, "paused").await;
    browser
        .wait(
            "three late jobs in the header",
            "return document.querySelector('[data-counter=\"jobs-late\"] b').textContent === '3'",
            10,
        )
        .await;

    // On the shelf, which runs: a sequence whose first position is not posted yet holds its
    // other members (`sequence`), and a job after one that has not completed waits for it
    // (`dependency`).
    let held = batch(
        &app,
        vec![
            json!({"kind": "retrieve", "reference": "SO-53-2", "from": loc(2, 5, 1, 1), "sequence": {"name": "SO-53", "position": 2}}),
            json!({"kind": "retrieve", "reference": "SO-53-3", "from": loc(2, 6, 1, 1), "sequence": {"name": "SO-53", "position": 3}}),
            json!({"kind": "store", "reference": "AFTER-1", "barcode": "BOX-D", "to": loc(1, 3, 3, 1), "after": ["SO-52-3"]}),
        ],
    )
    .await;
    let why = wait_sequence(&browser, "SO-53", "1:missing 2:waiting 3:waiting", 1, "not posted").await;
    assert!(why.contains("position 1"), "{why}");
    for (id, reason) in [(held[0], "sequence"), (held[1], "sequence"), (held[2], "dependency")] {
        let script = format!(
            "const c = document.querySelector('#attention .att-item[data-job-id=\"{id}\"][data-reason=\"{reason}\"]');
             const d = document.querySelector('tr[data-job-id=\"{id}\"] td.c-detail.reason-{reason}');
             return c && d && d.textContent.length > 0 && d.textContent;"
        );
        browser.wait(&format!("job {id} waiting: {reason}"), &script, 20).await;
    }
    let chip = browser.text("#attention-reasons [data-reason=\"sequence\"]").await;
    assert_eq!(chip, json!("2 sequence order"), "the reason chip in words");
    let chip = browser.text("#attention-reasons [data-reason=\"dependency\"]").await;
    assert_eq!(chip, json!("1 after another job"));
    let detail = browser.text(&format!("tr[data-job-id=\"{}\"] td.c-detail", held[2])).await;
    assert!(detail.as_str().unwrap().contains("SO-52-3"), "it names the job it waits for: {detail}");

    // The state filter finds the late jobs.
    browser.js("const s = document.getElementById('filter-state'); s.value = 'late'; s.dispatchEvent(new Event('change'));").await;
    let rows = browser
        .js("return [...document.querySelectorAll('#jobs tbody tr')].map((r) => Number(r.dataset.jobId))")
        .await;
    assert_eq!(rows, json!([late, ids[2], ids[1]]), "the unfinished late jobs, newest first");
    browser.js("const s = document.getElementById('filter-state'); s.value = ''; s.dispatchEvent(new Event('change'));").await;

    browser.screenshot_viewport("dashboard-orders.png").await;

    // On a tablet the panel is one column among the others, and nothing scrolls sideways.
    browser.viewport(800, 1200).await;
    let script = "return !document.getElementById('sequences-panel').hidden
        && document.documentElement.scrollWidth <= window.innerWidth";
    browser.wait("the tablet layout with the panel", script, 10).await;
    browser.js("document.getElementById('sequences-panel').scrollIntoView({ block: 'center' })").await;
    browser.screenshot_viewport("dashboard-orders-tablet.png").await;
    let toasts = browser.js("return [...document.querySelectorAll('.toast')].map(t => t.textContent)").await;
    assert_eq!(toasts, json!([]), "no error was shown on the page");
    browser.close().await;
    app.stop().await;
}
