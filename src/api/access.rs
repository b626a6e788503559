//! The access log: one line per answered request with its method, route, path, status and
//! latency, under the target `rackd::access`.
//!
//! Decisions where the spec is silent:
//! - The path is logged without its query: a query may carry `?token=KEY`, which must never
//!   reach a log. The route is the matched template (`/api/v1/jobs/{id}`), for grouping.
//! - Probes and scrapes (`/healthz`, `/readyz`, `/metrics`) log at DEBUG: a load balancer
//!   and a scraper asking every few seconds would otherwise fill most of the log. Answers
//!   of 5xx log at WARN, every other answer at INFO.
//! - `RACKD_LOG=info,rackd::access=warn` keeps only the failed requests.

use std::time::Instant;

use axum::extract::{MatchedPath, Request};
use axum::middleware::Next;
use axum::response::Response;

/// Paths asked by machines every few seconds: logged at DEBUG.
const PROBES: [&str; 3] = ["/healthz", "/readyz", "/metrics"];

/// Middleware: logs every request once it is answered.
pub async fn log(req: Request, next: Next) -> Response {
    let started = Instant::now();
    let method = req.method().clone();
    let path = req.uri().path().to_owned();
    let route = req.extensions().get::<MatchedPath>().map(|p| p.as_str().to_owned());
    let response = next.run(req).await;
    let status = response.status().as_u16();
    // Hundredths of a millisecond: finer is noise, and the line stays short.
    let latency_ms = (started.elapsed().as_secs_f64() * 1e5).round() / 100.0;
    let route = route.as_deref().unwrap_or("unmatched");
    if status >= 500 {
        tracing::warn!(target: "rackd::access", %method, route, %path, status, latency_ms, "request");
    } else if PROBES.contains(&path.as_str()) {
        tracing::debug!(target: "rackd::access", %method, route, %path, status, latency_ms, "request");
    } else {
        tracing::info!(target: "rackd::access", %method, route, %path, status, latency_ms, "request");
    }
    response
}
