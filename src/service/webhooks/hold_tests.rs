//! A deliverer held by its receiver (a request not yet answered) is no subscriber of the
//! hub: the hub keeps no commits for it and serializes none for it; caught up, it listens
//! again (a store, a writer, a hub and a receiver of its own, on real sockets).

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use tokio::sync::Semaphore;

use super::{Parts, Webhooks};
use crate::config::WebhookConfig;
use crate::service::events::Hub;
use crate::store::writer::{Hooks, Record, Writer};
use crate::store::{Database, open};

/// Waits up to 5 s for `done`, then says what it waited for.
async fn until(what: &str, done: impl Fn() -> bool) {
    for _ in 0..250 {
        if done() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    panic!("{what}: not within 5 s");
}

#[tokio::test]
async fn a_deliverer_held_by_its_receiver_holds_no_commits() {
    let dir = tempfile::tempdir().unwrap();
    let pool = open(&Database::Sqlite(dir.path().join("rackd.db")), Duration::from_secs(5)).await.unwrap();
    let hub = Hub::new(64, 0);
    let hooks = Hooks { publish: Some(hub.hook()), ..Hooks::default() };
    let (writer, _task) = Writer::start(&pool, 100, 100, hooks).await.unwrap();
    // Each answer takes a permit: none until the test hands them out.
    let answers = Arc::new(Semaphore::new(0));
    let received = Arc::new(AtomicUsize::new(0));
    let receiver = {
        let (answers, received) = (answers.clone(), received.clone());
        axum::Router::new().route(
            "/events",
            axum::routing::post(move || async move {
                received.fetch_add(1, Ordering::SeqCst);
                answers.acquire().await.unwrap().forget();
                axum::http::StatusCode::NO_CONTENT
            }),
        )
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}/events", listener.local_addr().unwrap());
    tokio::spawn(async move { axum::serve(listener, receiver).await });
    let config = WebhookConfig::new("wms", &url, &["*"], "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw");
    let parts = Parts { pool: pool.clone(), writer: writer.clone(), hub: hub.clone(), gate: None };
    let (webhooks, _tasks) = Webhooks::start(&[config], parts);
    until("the idle deliverer to listen to the hub", || hub.subscribers() == 1).await;

    writer.record(Record::Device { status: r#"{"n":0}"#.into() }).await.unwrap();
    until("the first event's request", || received.load(Ordering::SeqCst) == 1).await;
    for n in 1..4 {
        writer.record(Record::Device { status: format!(r#"{{"n":{n}}}"#) }).await.unwrap();
    }
    assert_eq!(hub.subscribers(), 0, "a deliverer waiting for its receiver listens to no commit");

    answers.add_permits(4);
    until("every event delivered", || webhooks.live()[0].1.row.cursor == 4).await;
    assert_eq!(received.load(Ordering::SeqCst), 4);
    until("the caught-up deliverer to listen again", || hub.subscribers() == 1).await;
    answers.add_permits(1);
    writer.record(Record::Device { status: r#"{"n":4}"#.into() }).await.unwrap();
    until("the next event, woken by its commit", || webhooks.live()[0].1.row.cursor == 5).await;
}
