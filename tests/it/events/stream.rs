//! Snapshot, live order, topic filters, bad requests and auth.

use std::time::Duration;

use rackd::store::Engine;
use rstest::rstest;
use serde_json::json;

use super::{assert_consecutive, assert_nothing_more, submit};
use crate::support::eventually;
use crate::support::ws::{Got, Ws};
use crate::support::{assert_error, spawn_app, spawn_with, store};

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn a_snapshot_then_every_event_in_order(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let before = submit(&app, 2).await;
    let mut ws = Ws::connect(&app.base, "").await;
    let snapshot = ws.json().await;
    assert_eq!(snapshot["type"], "snapshot", "{snapshot}");
    assert_eq!(snapshot["reason"], "requested");
    assert_eq!(snapshot["seq"], 2, "two jobs accepted before: two events");
    let data = &snapshot["data"];
    let ids: Vec<i64> = data["jobs"].as_array().unwrap().iter().map(|j| j["id"].as_i64().unwrap()).collect();
    assert_eq!(ids, vec![before[1], before[0]], "active jobs, newest first");
    assert_eq!(data["jobs_truncated"], false);
    assert_eq!(data["locations"].as_array().unwrap().len(), 2 * 10 * 6 * 4 + 2 * 20 * 8 * 2);
    assert_eq!(data["alarms"], json!([]));
    assert_eq!(data["devices"], json!([]), "the plain test config has no devices");

    let ids = submit(&app, 5).await;
    let (status, cancelled) = app.post(&format!("/api/v1/jobs/{}/cancel", ids[0]), &json!({})).await;
    assert_eq!(status, 200, "{cancelled}");
    let events = ws.events(7).await;
    assert_consecutive(&events, 3);
    for (event, id) in events.iter().zip(&ids) {
        assert_eq!(event["type"], "job.updated");
        assert_eq!(event["data"]["id"], *id);
        assert_eq!(event["data"]["state"], "queued");
        assert!(event["time"].as_str().unwrap().ends_with('Z'), "{event}");
    }
    assert_eq!(events[5]["data"]["id"], ids[0]);
    assert_eq!(events[5]["data"]["state"], "cancelled");
    // The cancel's audit entry, in the same commit; the submissions' are not published.
    assert_eq!(events[6]["type"], "audit.recorded");
    assert_eq!(events[6]["data"]["action"], "cancel");
    assert_eq!(events[6]["data"]["target"], format!("job:{}", ids[0]));
    assert_nothing_more(&app, &mut ws, 9).await;
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn topics_filter_both_snapshot_and_events(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let mut jobs_only = Ws::connect(&app.base, "?topics=jobs").await;
    let mut locations_only = Ws::connect(&app.base, "?topics=locations,alarms").await;
    let snapshot = jobs_only.json().await;
    let keys: Vec<&String> = snapshot["data"].as_object().unwrap().keys().collect();
    assert_eq!(keys, vec!["jobs", "jobs_truncated"], "{snapshot}");
    let snapshot = locations_only.json().await;
    let keys: Vec<&String> = snapshot["data"].as_object().unwrap().keys().collect();
    assert_eq!(keys, vec!["alarms", "locations"], "{snapshot}");

    submit(&app, 3).await;
    let events = jobs_only.events(3).await;
    assert!(events.iter().all(|e| e["type"] == "job.updated"));
    // The job events were broadcast to every session before the server stops, and a session
    // sends what it has before it closes: the first thing locations_only hears is the close.
    let stopping = tokio::spawn(app.stop());
    match locations_only.next(Duration::from_secs(10)).await {
        Got::Closed(code) => assert_eq!(code, 1001, "no job event reached the locations subscriber"),
        other => panic!("expected only the close, got {other:?}"),
    }
    stopping.await.unwrap();
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn bad_requests_are_json_errors(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let got = app.get("/api/v1/ws").await;
    assert_error(&got, 400, "websocket_required");
    let got = app.get("/api/v1/ws?topics=jobs,boxes").await;
    assert_error(&got, 400, "bad_query");
    assert!(got.1["error"]["message"].as_str().unwrap().contains("boxes"), "{got:?}");
    assert_error(&app.get("/api/v1/ws?since=-1").await, 400, "bad_query");
    assert_error(&app.get("/api/v1/ws?since=abc").await, 400, "bad_query");
    assert_error(&app.get("/api/v1/ws?colour=red").await, 400, "bad_query");
    assert!(matches!(Ws::try_connect(&app.base, "?topics=nope", None).await, Err(400)));
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn subscribers_need_a_viewer_key_in_a_header_or_the_query(#[case] engine: Engine) {
    use rackd::auth::{KeyHash, Role};
    use rackd::config::KeyConfig;
    let app = spawn_with(engine, |c| {
        c.auth.keys = vec![
            KeyConfig { name: "screen".into(), role: Role::Viewer, hash: KeyHash::of("screen-key") },
            KeyConfig { name: "odd".into(), role: Role::Viewer, hash: KeyHash::of("a+b/c=d%") },
        ];
    })
    .await;
    assert!(matches!(Ws::try_connect(&app.base, "", None).await, Err(401)));
    assert!(matches!(Ws::try_connect(&app.base, "?token=wrong", None).await, Err(401)));
    assert!(matches!(Ws::try_connect(&app.base, "", Some("wrong")).await, Err(401)));
    let mut by_query = Ws::try_connect(&app.base, "?token=screen-key", None).await.unwrap();
    let mut by_header = Ws::try_connect(&app.base, "", Some("screen-key")).await.unwrap();
    assert_eq!(by_query.json().await["type"], "snapshot");
    // The query is URL-decoded: a key with + / = % works when encoded.
    let mut encoded = Ws::try_connect(&app.base, "?token=a%2Bb%2Fc%3Dd%25", None).await.unwrap();
    assert_eq!(encoded.json().await["type"], "snapshot");
    assert_eq!(by_header.json().await["type"], "snapshot");
    // A viewer may watch but not submit.
    let (status, _) = app.post("/api/v1/jobs", &store("r1")).await;
    assert_eq!(status, 401);
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn subscribers_are_closed_when_the_server_stops(#[case] engine: Engine) {
    let app = spawn_app(engine).await;
    let mut ws = Ws::connect(&app.base, "").await;
    assert_eq!(ws.json().await["type"], "snapshot");
    let stopping = tokio::spawn(app.stop());
    match ws.next(Duration::from_secs(10)).await {
        Got::Closed(code) => assert_eq!(code, 1001),
        other => panic!("expected a close, got {other:?}"),
    }
    stopping.await.unwrap();
}

#[rstest]
#[case::sqlite(Engine::Sqlite)]
#[case::postgres(Engine::Postgres)]
#[tokio::test]
async fn pings_go_both_ways_and_a_silent_client_is_dropped(#[case] engine: Engine) {
    let app = spawn_with(engine, |c| c.events.ping_secs = 1).await;
    let mut ws = Ws::connect(&app.base, "").await;
    assert_eq!(ws.json().await["type"], "snapshot");
    assert!(ws.ping(Duration::from_secs(2)).await, "the server answers a ping at once");
    assert!(ws.pinged(Duration::from_secs(3)).await, "the server pings every ping_secs");

    // A client that reads nothing never answers a ping: dropped after two. The gauge of live
    // subscribers shows when its session starts and when the server drops it; only then is
    // its stream read (reading would answer the pings).
    let subscribers = || async {
        let text = app.client.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
        let line = text.lines().find(|l| l.starts_with("rackd_ws_subscribers ")).map(str::to_owned);
        line.and_then(|l| l.rsplit(' ').next().and_then(|n| n.parse::<i64>().ok())).expect("the gauge")
    };
    let wait_for = async |want: i64, what: &'static str| {
        eventually(what, Duration::from_secs(10), async || {
            let now = subscribers().await;
            if now == want { Ok(()) } else { Err(now) }
        })
        .await
    };
    let open = subscribers().await;
    ws.close().await;
    wait_for(open - 1, "the closed client's session to end").await;
    let (stream, _) =
        tokio_tungstenite::connect_async(crate::support::ws::url(&app.base, "/api/v1/ws")).await.unwrap();
    wait_for(open, "the silent client's session to start").await;
    wait_for(open - 1, "the silent client to be dropped").await;
    let mut stream = stream;
    let mut closed = false;
    while let Ok(Some(message)) =
        tokio::time::timeout(Duration::from_secs(2), futures::StreamExt::next(&mut stream)).await
    {
        match message {
            Ok(tokio_tungstenite::tungstenite::Message::Close(frame)) => {
                assert_eq!(frame.map(|f| u16::from(f.code)), Some(1001));
                closed = true;
                break;
            }
            Ok(_) => continue,
            Err(_) => break,
        }
    }
    assert!(closed, "the silent client was closed");
}
