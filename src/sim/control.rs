//! `rackd sim ... --control HOST:PORT`: a small HTTP/JSON surface to inspect and poke a
//! running simulator's memory, the way an engineer plays the field on a test bench.
//!
//! | route | what |
//! |-------|------|
//! | `GET /values?address=4x100&type=f32&word_order=cdab` | one value (`&count=N`: N values at consecutive addresses; `&length=N`: a string's characters) |
//! | `PUT /values` | a preset entry (`{"address", "type", "word_order", "value" or "values", "read_only"}`): writes it |
//! | `GET /read-only` | the read-only ranges, `[{"address", "count"}]` |
//! | `GET /counters` | `{"requests", "refused"}`: requests the server has seen, master writes refused |
//!
//! Answers are the entry shape of a preset, so what `GET` prints can be `PUT` back or
//! pasted into a preset. Writes here are the field's: they pass by the read-only ranges,
//! which refuse only a master's writes over the protocol. `read_only: true` in a `PUT`
//! protects the items after writing them. Errors are `{"error": {"code", "message"}}`
//! with status 400, as rackd's API answers, the message saying what is wrong.
//!
//! No authentication: the surface is for a bench, and listens where `--control` says
//! (give it a loopback address unless the bench is a network of its own).

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};

use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde::{Deserialize, Serialize};

use super::memory::SimMemory;
use super::preset::value::{Entry, Order, Resolved, Target, ValueType};
use super::preset::{ReadOnlyRange, range_span};
use crate::protocols::Protocol;
use crate::protocols::faults::SharedFaults;

/// What the control surface works on.
pub struct Control {
    /// The simulator's protocol (for its address notation).
    pub protocol: Protocol,
    /// Its memory.
    pub memory: Arc<dyn SimMemory>,
    /// Its faults, which count the requests the server has seen.
    pub faults: SharedFaults,
    /// The read-only ranges, as listed.
    pub read_only: Mutex<Vec<ReadOnlyRange>>,
}

type Shared = State<Arc<Control>>;

/// A refusal: 400 with the house's error body.
struct Refusal(String);

impl<E: std::fmt::Display> From<E> for Refusal {
    fn from(e: E) -> Self {
        Refusal(format!("{e:#}"))
    }
}

impl IntoResponse for Refusal {
    fn into_response(self) -> Response {
        let body = serde_json::json!({"error": {"code": "bad_request", "message": self.0}});
        (StatusCode::BAD_REQUEST, Json(body)).into_response()
    }
}

/// The query of `GET /values`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Read {
    address: String,
    #[serde(rename = "type")]
    ty: Option<ValueType>,
    word_order: Option<Order>,
    count: Option<u32>,
    length: Option<u16>,
}

async fn get_values(
    State(c): Shared,
    query: Result<Query<Read>, QueryRejection>,
) -> Result<Json<Entry>, Refusal> {
    let Query(q) = query.map_err(|e| e.body_text())?;
    let n = q.count.unwrap_or(1);
    let target = Target::new(c.protocol, c.memory.as_ref(), &q.address, q.ty, q.word_order, n, q.length)?;
    let mut values = target.read(c.memory.as_ref())?;
    let mut entry = Entry {
        address: q.address,
        ty: q.ty,
        word_order: q.word_order,
        length: q.length,
        ..Entry::default()
    };
    match q.count {
        Some(_) => entry.values = Some(values),
        None => entry.value = values.pop(),
    }
    Ok(Json(entry))
}

async fn put_values(
    State(c): Shared,
    body: Result<Json<Entry>, JsonRejection>,
) -> Result<Json<Entry>, Refusal> {
    let Json(entry) = body.map_err(|e| e.body_text())?;
    let resolved = Resolved::new(c.protocol, c.memory.as_ref(), &entry)?;
    let mut listed = c.read_only.lock().unwrap_or_else(|p| p.into_inner());
    let range = ReadOnlyRange { address: entry.address.clone(), count: resolved.target.items() };
    if entry.read_only {
        // Checked before writing, so a refused PUT leaves memory as it was.
        let span = range_span(c.protocol, c.memory.as_ref(), &range)?;
        for other in listed.iter() {
            if range_span(c.protocol, c.memory.as_ref(), other)?.overlaps(&span) {
                return Err(Refusal(format!(
                    "overlaps the read-only range {} count {}",
                    other.address, other.count
                )));
            }
        }
    }
    resolved.write(c.memory.as_ref())?;
    if entry.read_only {
        let at = crate::protocols::notation::shape(c.protocol, &range.address)?.address;
        c.memory.protect(&at, range.count)?;
        listed.push(range);
    }
    Ok(Json(entry))
}

async fn get_read_only(State(c): Shared) -> Json<Vec<ReadOnlyRange>> {
    Json(c.read_only.lock().unwrap_or_else(|p| p.into_inner()).clone())
}

/// The answer of `GET /counters`.
#[derive(Serialize)]
struct Counters {
    requests: u64,
    refused: u64,
}

async fn get_counters(State(c): Shared) -> Json<Counters> {
    Json(Counters { requests: c.faults.requests_seen(), refused: c.memory.refused() })
}

/// The control surface's routes.
pub fn router(control: Arc<Control>) -> Router {
    Router::new()
        .route("/values", get(get_values).put(put_values))
        .route("/read-only", get(get_read_only))
        .route("/counters", get(get_counters))
        .with_state(control)
}

/// A running control surface; dropping it stops it.
pub struct ControlServer {
    local_addr: SocketAddr,
    task: tokio::task::JoinHandle<()>,
}

impl ControlServer {
    /// Serves the control surface on `listen` (port 0 picks a free port).
    pub async fn start(listen: SocketAddr, control: Control) -> anyhow::Result<ControlServer> {
        let listener = tokio::net::TcpListener::bind(listen).await?;
        let local_addr = listener.local_addr()?;
        let app = router(Arc::new(control));
        let task = tokio::spawn(async move {
            if let Err(e) = axum::serve(listener, app).await {
                tracing::warn!(error = %e, "simulator control surface stopped");
            }
        });
        Ok(ControlServer { local_addr, task })
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }
}

impl Drop for ControlServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}
