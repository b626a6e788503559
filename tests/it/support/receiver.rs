//! A WMS's webhook receiver for tests: axum on 127.0.0.1 that checks every request's
//! Standard Webhooks signature and records it, and misbehaves on demand: fails a share of
//! calls with 500, answers a share too late (after rackd's timeout), answers every call
//! after a delay, answers 410 Gone, or goes down (new connections refused, open ones cut)
//! for a while, its port held meanwhile ([`HeldPort`]) for it to come back on.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use rackd::service::webhooks::sign::verify;
use serde_json::Value;
use tokio::net::TcpListener;
use tokio::task::JoinSet;

use super::held::HeldPort;

/// A test secret, as a WMS would be given it.
pub const SECRET: &str = "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw";

/// How the receiver behaves now.
#[derive(Clone, Debug, Default)]
pub struct Mode {
    /// Share of calls answered 500.
    pub fail: f64,
    /// Share of calls answered after `late`.
    pub late_share: f64,
    /// How late those are.
    pub late: Duration,
    /// Every answer waits this long.
    pub delay: Duration,
    /// Answer 410 Gone.
    pub gone: bool,
}

/// One request as received.
#[derive(Clone, Debug)]
pub struct Received {
    /// `webhook-id`.
    pub id: String,
    /// The body's `seq`.
    pub seq: i64,
    /// The body's `type`.
    pub kind: String,
    /// The body, as sent.
    pub body: Bytes,
    /// Whether the signature verified.
    pub valid: bool,
    /// The status it was answered with.
    pub status: u16,
    /// Answered after `Mode::late` (past rackd's timeout: rackd never saw the answer).
    pub late: bool,
}

#[derive(Default)]
struct Shared {
    mode: Mode,
    received: Vec<Received>,
}

/// A running receiver.
pub struct Receiver {
    pub addr: SocketAddr,
    /// Its port, held while it is down (nothing else can take it meanwhile).
    port: HeldPort,
    shared: Arc<Mutex<Shared>>,
    server: Option<tokio::task::JoinHandle<()>>,
    /// The server last stopped, until it has let go of its listener.
    stopping: Option<tokio::task::JoinHandle<()>>,
}

impl Receiver {
    /// A receiver on a free port, answering 200 at once.
    pub async fn start() -> Receiver {
        let port = HeldPort::new();
        let addr = port.addr();
        let shared = Arc::new(Mutex::new(Shared::default()));
        let server = Some(tokio::spawn(serve(port.listen(), shared.clone())));
        Receiver { addr, port, shared, server, stopping: None }
    }

    /// Its URL.
    pub fn url(&self) -> String {
        format!("http://{}/events", self.addr)
    }

    /// Behaves as `mode` from now on.
    pub fn set(&self, mode: Mode) {
        self.shared.lock().unwrap().mode = mode;
    }

    /// Refuses connections and cuts the open ones until [`Receiver::up`].
    pub fn down(&mut self) {
        if let Some(server) = self.server.take() {
            server.abort();
            self.stopping = Some(server);
        }
    }

    /// Serves again on the same port, once the last server has let go of its listener.
    pub async fn up(&mut self) {
        self.down();
        if let Some(stopping) = self.stopping.take() {
            let _ = stopping.await;
        }
        self.server = Some(tokio::spawn(serve(self.port.listen(), self.shared.clone())));
    }

    /// Every request so far, in arrival order.
    pub fn received(&self) -> Vec<Received> {
        self.shared.lock().unwrap().received.clone()
    }

    /// The seqs acknowledged (answered 2xx in time), each once.
    pub fn acked(&self) -> std::collections::BTreeSet<i64> {
        self.received().iter().filter(|r| r.status < 300 && !r.late).map(|r| r.seq).collect()
    }

    /// Checks what every delivery must be whatever the receiver did: each signature valid,
    /// each event of a type the subscription takes (`prefix`), each `webhook-id` naming one
    /// event (`NAME-SEQ`) with one body however often it came, and each event arriving for
    /// the first time after every event before it.
    pub fn check(&self, name: &str, prefix: &str) {
        let received = self.received();
        let foreign: Vec<_> =
            received.iter().filter(|r| !r.kind.starts_with(prefix)).map(|r| &r.kind).collect();
        assert!(foreign.is_empty(), "types the subscription does not take: {foreign:?}");
        let invalid: Vec<_> = received.iter().filter(|r| !r.valid).map(|r| &r.id).collect();
        assert!(invalid.is_empty(), "signatures that do not verify: {invalid:?}");
        let mut bodies: BTreeMap<&str, &Bytes> = BTreeMap::new();
        for r in &received {
            assert_eq!(r.id, format!("{name}-{}", r.seq), "webhook-id names the subscription and the event");
            let first = bodies.entry(&r.id).or_insert(&r.body);
            assert_eq!(*first, &r.body, "a duplicate of {} with another body", r.id);
        }
        let mut firsts: Vec<i64> = Vec::new();
        for r in &received {
            if !firsts.contains(&r.seq) {
                firsts.push(r.seq);
            }
        }
        assert!(
            firsts.windows(2).all(|w| w[0] < w[1]),
            "events came for the first time out of order: {firsts:?}"
        );
    }
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.down();
    }
}

/// Accepts until aborted; aborting drops the connections' tasks with it.
async fn serve(listener: TcpListener, shared: Arc<Mutex<Shared>>) {
    let app = axum::Router::new().route("/events", axum::routing::post(receive)).with_state(shared);
    let mut connections = JoinSet::new();
    loop {
        let Ok((stream, _)) = listener.accept().await else { continue };
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        connections.spawn(async move {
            let io = hyper_util::rt::TokioIo::new(stream);
            let _ = hyper::server::conn::http1::Builder::new().serve_connection(io, service).await;
        });
        while connections.try_join_next().is_some() {}
    }
}

async fn receive(State(shared): State<Arc<Mutex<Shared>>>, headers: HeaderMap, body: Bytes) -> StatusCode {
    let header = |name: &str| headers.get(name).and_then(|v| v.to_str().ok()).unwrap_or_default().to_owned();
    let (id, timestamp, signature) =
        (header("webhook-id"), header("webhook-timestamp"), header("webhook-signature"));
    let key = rackd::config::webhooks::decode_secret(SECRET).unwrap();
    let valid = timestamp.parse().is_ok_and(|t| verify(&key, &id, t, &body, &signature));
    let event: Value = serde_json::from_slice(&body).unwrap_or_default();
    let mode = shared.lock().unwrap().mode.clone();
    let roll: f64 = rand::random();
    let (status, late) = if mode.gone {
        (StatusCode::GONE, false)
    } else if roll < mode.fail {
        (StatusCode::INTERNAL_SERVER_ERROR, false)
    } else {
        (StatusCode::OK, roll < mode.fail + mode.late_share)
    };
    let wait = if late { mode.late } else { mode.delay };
    tokio::time::sleep(wait).await;
    // Recorded once answered; a late answer is one rackd gave up on (the receiver acted on
    // it all the same: the event comes again, with the same id).
    let received = Received {
        id,
        seq: event["seq"].as_i64().unwrap_or(-1),
        kind: event["type"].as_str().unwrap_or_default().to_owned(),
        body,
        valid,
        status: status.as_u16(),
        late,
    };
    shared.lock().unwrap().received.push(received);
    status
}
