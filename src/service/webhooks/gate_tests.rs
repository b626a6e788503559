//! The lease's gate holds deliveries: a node that may not drive the machines sends nothing,
//! with events waiting; the moment it may, it delivers them (a store, a writer, a hub and
//! a receiver of its own, on real sockets).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use super::{Parts, Webhooks};
use crate::config::WebhookConfig;
use crate::service::events::Hub;
use crate::store::writer::{Hooks, Record, Writer};
use crate::store::{Database, open};

#[tokio::test]
async fn a_node_that_may_not_drive_sends_nothing_until_it_may() {
    let dir = tempfile::tempdir().unwrap();
    let pool = open(&Database::Sqlite(dir.path().join("rackd.db")), Duration::from_secs(5)).await.unwrap();
    let hub = Hub::new(64, 0);
    let hooks = Hooks { publish: Some(hub.hook()), ..Hooks::default() };
    let (writer, _task) = Writer::start(&pool, 100, 100, hooks).await.unwrap();
    let received = Arc::new(AtomicUsize::new(0));
    let counted = received.clone();
    let receiver = axum::Router::new().route(
        "/events",
        axum::routing::post(move || {
            counted.fetch_add(1, Ordering::SeqCst);
            async { axum::http::StatusCode::NO_CONTENT }
        }),
    );
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let url = format!("http://{}/events", listener.local_addr().unwrap());
    tokio::spawn(async move { axum::serve(listener, receiver).await });
    let may = Arc::new(AtomicBool::new(false));
    let gate = {
        let may = may.clone();
        Some(Arc::new(move || may.load(Ordering::SeqCst)) as crate::devices::gate::MayDrive)
    };
    let config = WebhookConfig::new("wms", &url, &["*"], "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw");
    let parts = Parts { pool: pool.clone(), writer: writer.clone(), hub, gate };
    let (webhooks, _tasks) = Webhooks::start(&[config], parts);
    // Started (a new subscription starts from the newest event when its task first runs).
    for _ in 0..100 {
        if !webhooks.live()[0].1.row.name.is_empty() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    for n in 0..3 {
        writer.record(Record::Device { status: format!(r#"{{"n":{n}}}"#) }).await.unwrap();
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(received.load(Ordering::SeqCst), 0, "sent while the gate was shut");
    assert_eq!(webhooks.live()[0].1.row.cursor, 0, "nothing acknowledged");
    may.store(true, Ordering::SeqCst);
    for _ in 0..100 {
        if received.load(Ordering::SeqCst) == 3 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(received.load(Ordering::SeqCst), 3, "every event once the gate opened");
}
