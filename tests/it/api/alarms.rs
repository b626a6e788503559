//! Alarms an operator can act on: plain text, what to do and the protocol detail; the
//! acknowledgement (operators only, audited, published); the CSV export; and `whoami`.

use std::time::Duration;

use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::store::Engine;
use rstest::rstest;
use serde_json::{Value, json};

use super::demo::{FAST, demo_app};
use crate::support::eventually;
use crate::support::ws::{Got, Ws};
use crate::support::{TestApp, assert_error, spawn_app, spawn_with, split};

/// A key name a CSV writer must quote: a comma, quotes and a line break.
const AWKWARD: &str = "night, \"B\"\nshift";

fn key(name: &str, secret: &str, role: Role) -> KeyConfig {
    KeyConfig { name: name.into(), role, hash: KeyHash::of(secret) }
}

async fn send(
    app: &TestApp,
    method: &str,
    path: &str,
    key: Option<&str>,
    body: Option<Value>,
) -> (u16, Value) {
    let mut req = app.client.request(method.parse().unwrap(), app.url(path));
    if let Some(k) = key {
        req = req.bearer_auth(k);
    }
    if let Some(b) = body {
        req = req.json(&b);
    }
    split(req.send().await.unwrap()).await
}

/// The active alarm of `device` with `code`, once it is there.
async fn active_alarm(app: &TestApp, key: &str, code: u64) -> Value {
    eventually(format!("an active alarm {code}"), Duration::from_secs(10), async || {
        let (status, page) = send(app, "GET", "/api/v1/alarms?active=true", Some(key), None).await;
        assert_eq!(status, 200, "{page}");
        page["alarms"].as_array().unwrap().iter().find(|a| a["code"] == code).cloned().ok_or(page)
    })
    .await
}

/// RFC 4180 records: quoted fields may hold commas, doubled quotes and line breaks.
fn parse_csv(text: &str) -> Vec<Vec<String>> {
    let (mut records, mut record, mut field) = (Vec::new(), Vec::new(), String::new());
    let mut chars = text.chars().peekable();
    let mut quoted = false;
    while let Some(c) = chars.next() {
        match (quoted, c) {
            (true, '"') if chars.peek() == Some(&'"') => {
                chars.next();
                field.push('"');
            }
            (true, '"') => quoted = false,
            (true, c) => field.push(c),
            (false, '"') => quoted = true,
            (false, ',') => record.push(std::mem::take(&mut field)),
            (false, '\r') => {}
            (false, '\n') => {
                record.push(std::mem::take(&mut field));
                records.push(std::mem::take(&mut record));
            }
            (false, c) => field.push(c),
        }
    }
    assert!(field.is_empty() && record.is_empty(), "the export ends with a line break: {text}");
    records
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_alarm_says_what_to_do_and_an_operator_acknowledges_it(#[case] engine: Engine) {
    let (app, sims) = demo_app(engine, FAST, |c| {
        c.auth.keys = vec![key("watcher", "key-v", Role::Viewer), key(AWKWARD, "key-o", Role::Operator)];
    })
    .await;
    sims.crane.raise_alarm(7011);
    let alarm = active_alarm(&app, "key-v", 7011).await;
    assert_eq!(alarm["text"], "crane1 reports alarm 7011: travel inverter fault", "{alarm}");
    assert_eq!(alarm["detail"], "D205 = 7011 (hardware alarm in the crane's catalogue)");
    assert!(alarm["action"].as_str().unwrap().starts_with("A person must"), "{alarm}");
    assert_eq!(
        (alarm["acknowledged_by"].clone(), alarm["acknowledged_at"].clone()),
        (Value::Null, Value::Null)
    );
    let id = alarm["id"].as_i64().unwrap();
    let ack = format!("/api/v1/alarms/{id}/acknowledge");

    let mut ws = Ws::connect(&app.base, "?topics=alarms&token=key-v").await;
    ws.json().await; // the snapshot
    assert_error(&send(&app, "POST", &ack, Some("key-v"), None).await, 403, "forbidden");
    assert_error(&send(&app, "POST", &ack, None, None).await, 401, "unauthorized");
    let note = json!({"note": "inverter reset by the night shift"});
    let (status, done) = send(&app, "POST", &ack, Some("key-o"), Some(note)).await;
    assert_eq!(status, 200, "{done}");
    assert_eq!(done["acknowledged_by"], AWKWARD);
    assert!(done["acknowledged_at"].is_string() && done["cleared_at"].is_null(), "still active: {done}");
    assert_error(&send(&app, "POST", &ack, Some("key-o"), None).await, 409, "already_acknowledged");
    assert_error(
        &send(&app, "POST", "/api/v1/alarms/999999/acknowledge", Some("key-o"), None).await,
        404,
        "not_found",
    );
    assert_error(
        &send(&app, "POST", &ack, Some("key-o"), Some(json!({"note": "x".repeat(501)}))).await,
        422,
        "invalid_reason",
    );
    let event = loop {
        match ws.next(Duration::from_secs(10)).await {
            Got::Json(m) if m["type"] == "alarm.updated" => break m,
            Got::Json(_) => {}
            other => panic!("no alarm.updated: {other:?}"),
        }
    };
    assert_eq!(
        (event["data"]["id"].clone(), event["data"]["acknowledged_by"].clone()),
        (json!(id), json!(AWKWARD))
    );
    let (_, audit) = send(&app, "GET", "/api/v1/audit", Some("key-v"), None).await;
    let entry = &audit["entries"][0];
    assert_eq!(
        (entry["action"].clone(), entry["target"].clone(), entry["by"].clone(), entry["reason"].clone()),
        (
            json!("acknowledge"),
            json!(format!("alarm:{id}")),
            json!(AWKWARD),
            json!("inverter reset by the night shift")
        ),
        "{audit}"
    );

    // The export: a header, then the alarm, its awkward acknowledger quoted.
    sims.crane.clear_alarm();
    let r = app.client.get(app.url("/api/v1/alarms/export.csv")).bearer_auth("key-v").send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert!(r.headers()["content-type"].to_str().unwrap().starts_with("text/csv"));
    let text = r.text().await.unwrap();
    assert!(text.contains("\"night, \"\"B\"\"\nshift\""), "quoted, quotes doubled: {text}");
    let records = parse_csv(&text);
    assert_eq!(
        records[0].join(","),
        "id,device,kind,code,class,text,detail,raised_at,cleared_at,acknowledged_by,acknowledged_at"
    );
    let row = records.iter().find(|r| r[0] == id.to_string()).unwrap_or_else(|| panic!("{text}"));
    assert_eq!(row.len(), 11, "{row:?}");
    assert_eq!(
        (&row[1][..], &row[2][..], &row[3][..], &row[4][..]),
        ("crane1", "device", "7011", "hardware")
    );
    assert_eq!(row[5], "crane1 reports alarm 7011: travel inverter fault");
    assert_eq!(row[9], AWKWARD);
    assert!(!row[7].is_empty() && !row[10].is_empty(), "{row:?}");
    let future = "/api/v1/alarms/export.csv?since=2999-01-01T00:00:00Z";
    let r = app.client.get(app.url(future)).bearer_auth("key-v").send().await.unwrap();
    assert_eq!(parse_csv(&r.text().await.unwrap()).len(), 1, "only the header");
    let backwards = "/api/v1/alarms/export.csv?since=2026-01-02T00:00:00Z&until=2026-01-01T00:00:00Z";
    assert_error(&send(&app, "GET", backwards, Some("key-v"), None).await, 400, "bad_query");
    assert_error(
        &send(&app, "GET", "/api/v1/alarms/export.csv?since=soon", Some("key-v"), None).await,
        400,
        "bad_query",
    );
    app.stop().await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn whoami_names_the_key_and_its_role(#[case] engine: Engine) {
    let app = spawn_with(engine, |c| {
        c.auth.keys = vec![
            key("desk", "key-v", Role::Viewer),
            key("lead", "key-o", Role::Operator),
            key("root", "key-a", Role::Admin),
        ];
    })
    .await;
    for (secret, name, role) in
        [("key-v", "desk", "viewer"), ("key-o", "lead", "operator"), ("key-a", "root", "admin")]
    {
        let got = send(&app, "GET", "/api/v1/whoami", Some(secret), None).await;
        assert_eq!(got, (200, json!({"name": name, "role": role})));
    }
    assert_error(&send(&app, "GET", "/api/v1/whoami", None, None).await, 401, "unauthorized");
    assert_error(&send(&app, "GET", "/api/v1/whoami", Some("nope"), None).await, 401, "unauthorized");
    app.stop().await;

    let open = spawn_app(engine).await;
    assert_eq!(open.get("/api/v1/whoami").await, (200, json!({"name": "anonymous", "role": "admin"})));
    open.stop().await;
}

/// An export longer than the pages it is read in (1000 alarms) holds every alarm of its
/// period once, in order, and nothing outside it.
#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_long_export_holds_its_whole_period_in_order(#[case] engine: Engine) {
    use rackd::store::{self, Pool};
    let app = spawn_with(engine, |c| c.devices = Vec::new()).await;
    let pool = store::open(&app.db, Duration::from_secs(5)).await.unwrap();
    // 2,345 past alarms, one a second from 1_700_000_001_000 ms on.
    let sql = "WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < 2345) \
               INSERT INTO alarms (id, device, code, class, text, raised_at, cleared_at, kind) \
               SELECT i, 'shelf1', 0, 'link', 'alarm ' || i, 1700000000000 + i * 1000, \
               1700000000000 + i * 1000 + 500, 'link' FROM n";
    match &pool {
        Pool::Sqlite(p) => drop(sqlx::query(sql).execute(p).await.unwrap()),
        Pool::Postgres(p) => drop(sqlx::query(sql).execute(p).await.unwrap()),
    }
    let ids = async |query: &str| {
        let r = app.client.get(app.url(&format!("/api/v1/alarms/export.csv{query}"))).send().await.unwrap();
        assert_eq!(r.status(), 200);
        let records = parse_csv(&r.text().await.unwrap());
        assert!(records[0][0] == "id", "{:?}", records[0]);
        records[1..].iter().map(|r| r[0].parse::<i64>().unwrap()).collect::<Vec<_>>()
    };
    let same = |got: Vec<i64>, want: std::ops::Range<i64>| {
        let ends = |v: &[i64]| (v.len(), v.first().copied(), v.last().copied());
        assert!(got.iter().copied().eq(want.clone()), "got {:?}, want {:?}", ends(&got), want);
    };
    same(ids("").await, 1..2346);
    let at = |i: i64| {
        let t = time::OffsetDateTime::from_unix_timestamp_nanos(
            (1_700_000_000_000 + i * 1000) as i128 * 1_000_000,
        );
        t.unwrap().format(&time::format_description::well_known::Rfc3339).unwrap()
    };
    let period = format!("?since={}&until={}", at(1000), at(2100));
    same(ids(&period).await, 1000..2100);
    same(ids(&format!("?until={}", at(1))).await, 0..0);
    app.stop().await;
    pool.close().await;
}
