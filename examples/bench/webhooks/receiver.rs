//! The WMS's end of `bench webhooks`: hyper on 127.0.0.1:0 that checks each request's
//! Standard Webhooks signature, answers 200 (at once, or after a delay), and records when
//! each event arrived. Its own small receiver, not the tests' (`tests/it/support/receiver.rs`
//! misbehaves in ways a benchmark does not need and keeps every body).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use rackd::service::webhooks::sign::verify;
use serde::Deserialize;
use tokio::net::TcpListener;
use tokio::sync::watch;

/// The subscription's secret, as a WMS would be given it.
pub const SECRET: &str = "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw";

/// One request as it arrived.
#[derive(Clone, Debug)]
pub struct Arrival {
    /// The event's `seq`.
    pub seq: i64,
    /// The job its `data` is about (`data.id`), if any.
    pub job: Option<i64>,
    /// The event's `time` (its commit, as the writer stamps it), Unix ms.
    pub time_ms: Option<i64>,
    /// When the request reached the handler.
    pub at: Instant,
    /// The same, on the wall clock (Unix ms, to the µs), comparable with `time_ms`.
    pub wall_ms: f64,
    /// Whether the signature verified and `webhook-id` named the event.
    pub valid: bool,
}

struct Shared {
    key: Vec<u8>,
    delay: Duration,
    arrivals: Mutex<Vec<Arrival>>,
    last_body: Mutex<Bytes>,
    count: watch::Sender<usize>,
    connections: AtomicU64,
}

/// A running receiver; it stops when dropped.
pub struct Receiver {
    url: String,
    shared: Arc<Shared>,
    server: tokio::task::JoinHandle<()>,
}

impl Receiver {
    /// A receiver on a free port that answers each request after `delay`.
    pub async fn start(delay: Duration) -> anyhow::Result<Receiver> {
        let listener = TcpListener::bind("127.0.0.1:0").await?;
        let url = format!("http://{}/events", listener.local_addr()?);
        let shared = Arc::new(Shared {
            key: rackd::config::webhooks::decode_secret(SECRET).map_err(anyhow::Error::msg)?,
            delay,
            arrivals: Mutex::new(Vec::new()),
            last_body: Mutex::new(Bytes::new()),
            count: watch::Sender::new(0),
            connections: AtomicU64::new(0),
        });
        let server = tokio::spawn(serve(listener, shared.clone()));
        Ok(Receiver { url, shared, server })
    }

    /// Where it receives.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Requests received so far.
    pub fn count(&self) -> usize {
        *self.shared.count.borrow()
    }

    /// Waits until `n` requests have arrived, at most `limit`.
    pub async fn wait_for(&self, n: usize, limit: Duration) -> anyhow::Result<()> {
        let mut count = self.shared.count.subscribe();
        match tokio::time::timeout(limit, count.wait_for(|&c| c >= n)).await {
            Ok(Ok(_)) => Ok(()),
            _ => anyhow::bail!("the receiver has {} requests after {limit:?}, not {n}", self.count()),
        }
    }

    /// The requests from the `from`th on, in arrival order.
    pub fn arrivals(&self, from: usize) -> Vec<Arrival> {
        let arrivals = self.shared.arrivals.lock().expect("the receiver's lock");
        arrivals.get(from..).unwrap_or_default().to_vec()
    }

    /// The body of the last request.
    pub fn last_body(&self) -> Bytes {
        self.shared.last_body.lock().expect("the receiver's lock").clone()
    }

    /// Connections accepted so far.
    pub fn connections(&self) -> u64 {
        self.shared.connections.load(Ordering::Relaxed)
    }
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.server.abort();
    }
}

/// A URL nothing listens on: a port bound and let go (connections are refused).
pub fn refusing_url() -> anyhow::Result<String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
    Ok(format!("http://127.0.0.1:{port}/events"))
}

/// Accepts until aborted (which drops the connections' tasks with it).
async fn serve(listener: TcpListener, shared: Arc<Shared>) {
    let app = axum::Router::new().route("/events", axum::routing::post(receive)).with_state(shared.clone());
    let mut connections = tokio::task::JoinSet::new();
    loop {
        let Ok((stream, _)) = listener.accept().await else { continue };
        // As a WMS behind any ordinary server would: small answers go out at once.
        let _ = stream.set_nodelay(true);
        shared.connections.fetch_add(1, Ordering::Relaxed);
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        connections.spawn(async move {
            let io = hyper_util::rt::TokioIo::new(stream);
            let _ = hyper::server::conn::http1::Builder::new().serve_connection(io, service).await;
        });
        while connections.try_join_next().is_some() {}
    }
}

/// The fields of an event the benchmark reads.
#[derive(Deserialize)]
struct Event<'a> {
    seq: i64,
    #[serde(borrow)]
    time: &'a str,
    #[serde(default)]
    data: Data,
}

#[derive(Default, Deserialize)]
struct Data {
    id: Option<i64>,
}

async fn receive(State(shared): State<Arc<Shared>>, headers: HeaderMap, body: Bytes) -> StatusCode {
    let at = Instant::now();
    let wall_ms =
        SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64() * 1e3);
    let header = |name: &str| headers.get(name).and_then(|v| v.to_str().ok()).unwrap_or_default();
    let (id, timestamp) = (header("webhook-id"), header("webhook-timestamp"));
    let signed =
        timestamp.parse().is_ok_and(|t| verify(&shared.key, id, t, &body, header("webhook-signature")));
    let event: Option<Event> = serde_json::from_slice(&body).ok();
    let arrival = Arrival {
        seq: event.as_ref().map_or(-1, |e| e.seq),
        job: event.as_ref().and_then(|e| e.data.id),
        time_ms: event.as_ref().and_then(|e| unix_ms(e.time)),
        at,
        wall_ms,
        valid: signed && event.as_ref().is_some_and(|e| id.ends_with(&format!("-{}", e.seq))),
    };
    shared.arrivals.lock().expect("the receiver's lock").push(arrival);
    *shared.last_body.lock().expect("the receiver's lock") = body;
    shared.count.send_modify(|c| *c += 1);
    if !shared.delay.is_zero() {
        tokio::time::sleep(shared.delay).await;
    }
    StatusCode::OK
}

/// An RFC 3339 time as Unix milliseconds.
fn unix_ms(text: &str) -> Option<i64> {
    let t = time::OffsetDateTime::parse(text, &time::format_description::well_known::Rfc3339).ok()?;
    Some((t.unix_timestamp_nanos() / 1_000_000) as i64)
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_event_s_time_is_read_to_the_millisecond() {
        assert_eq!(super::unix_ms("2026-11-21T08:00:00.123Z"), Some(1_795_248_000_123));
        assert_eq!(super::unix_ms("yesterday"), None);
    }
}
