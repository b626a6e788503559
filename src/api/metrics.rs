//! Prometheus metrics: HTTP requests by route and status, jobs by state, intake latency,
//! live event subscribers.

use axum::extract::{MatchedPath, Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

use super::error::ApiError;
use super::state::AppState;
use crate::domain::JobState;
use crate::store::jobs;

/// Labels of the request counter.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RequestLabels {
    method: String,
    route: String,
    status: u16,
}

/// Labels of the jobs gauge.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StateLabels {
    state: &'static str,
}

/// The service's metrics.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    jobs: Family<StateLabels, Gauge>,
    subscribers: Gauge,
    /// Seconds from a submission reaching the writer to its commit.
    pub intake_seconds: Histogram,
}

impl Default for Metrics {
    fn default() -> Self {
        let mut registry = Registry::with_prefix("rackd");
        let requests = Family::<RequestLabels, Counter>::default();
        let jobs = Family::<StateLabels, Gauge>::default();
        let intake_seconds = Histogram::new(exponential_buckets(0.0001, 2.0, 16));
        registry.register("http_requests", "HTTP requests by method, route and status", requests.clone());
        registry.register("jobs", "Jobs by state", jobs.clone());
        registry.register("intake_seconds", "Time from submission to durable commit", intake_seconds.clone());
        let subscribers = Gauge::default();
        registry.register("ws_subscribers", "WebSocket subscribers to live events", subscribers.clone());
        Metrics { registry, requests, jobs, subscribers, intake_seconds }
    }
}

/// Middleware: counts every request by method, matched route and status.
pub async fn count_requests(State(app): State<AppState>, req: Request, next: Next) -> Response {
    let method = req.method().to_string();
    let route = req.extensions().get::<MatchedPath>().map_or("unmatched", |p| p.as_str()).to_owned();
    let response = next.run(req).await;
    let labels = RequestLabels { method, route, status: response.status().as_u16() };
    app.metrics.requests.get_or_create(&labels).inc();
    response
}

/// `GET /metrics`: Prometheus text.
pub async fn metrics(State(app): State<AppState>) -> Result<Response, ApiError> {
    let counts = jobs::count_by_state(&app.pool).await?;
    for state in JobState::ALL {
        let n = counts.iter().find(|(s, _)| s == state.as_str()).map_or(0, |(_, n)| *n);
        app.metrics.jobs.get_or_create(&StateLabels { state: state.as_str() }).set(n);
    }
    app.metrics.subscribers.set(app.hub.subscribers() as i64);
    let mut text = String::new();
    prometheus_client::encoding::text::encode(&mut text, &app.metrics.registry)
        .map_err(|e| ApiError::unavailable(format!("metrics encoding: {e}")))?;
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4; charset=utf-8")], text).into_response())
}
