//! Operations: liveness, readiness, metrics, fallbacks.

use axum::extract::{MatchedPath, Request, State};
use axum::http::{HeaderMap, Method, Uri, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

use super::error::{ApiError, ErrorBody};
use super::extract::Json;
use super::state::AppState;

/// A health answer.
#[derive(Serialize, ToSchema)]
#[schema(example = json!({"status": "ok"}))]
pub struct Health {
    /// `ok`.
    pub status: &'static str,
    /// In a cluster (`/readyz`): `active` (this node drives the machines) or `standby`
    /// (it serves the API and stands by); absent for a node of its own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub role: Option<&'static str>,
}

/// Liveness: the process answers HTTP.
#[utoipa::path(get, path = "/healthz", tag = "operations", security(()),
    responses((status = 200, description = "Alive", body = Health)))]
pub async fn healthz() -> Json<Health> {
    Json(Health { status: "ok", role: None })
}

/// Readiness: the database answers, every migration is applied and the job writer runs
/// (the devices are not judged here: see `GET /api/v1/health`). A standby node of a
/// cluster is ready (it serves the whole API) and says so in `role`.
#[utoipa::path(get, path = "/readyz", tag = "operations", security(()),
    responses(
        (status = 200, description = "Ready", body = Health),
        (status = 503, description = "Not ready, with the reason", body = ErrorBody),
    ))]
pub async fn readyz(State(app): State<AppState>) -> Result<Json<Health>, ApiError> {
    // A store that cannot commit is told from memory, without waiting for a database that
    // may not answer (see `store_now`).
    let (ready, fault) = super::health::store_now(&app).await;
    if let Some(fault) = fault {
        tracing::error!(store = fault.cause.as_str(), "not ready: the store cannot commit");
        return Err(ApiError::new(
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            "not_ready",
            format!("the store cannot commit: {}", fault.cause.words()),
        ));
    }
    ready.map_err(|e| {
        // The cause goes to the log; the answer names no driver text.
        tracing::error!(error = %e, "not ready");
        let message = match e {
            crate::store::NotReady::Unreachable(_) => "the database does not answer",
            crate::store::NotReady::Migration { .. } => "the database schema is not up to date",
        };
        ApiError::new(axum::http::StatusCode::SERVICE_UNAVAILABLE, "not_ready", message)
    })?;
    if !app.writer.is_running() {
        tracing::error!("not ready: the job writer has stopped");
        return Err(ApiError::new(
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            "not_ready",
            "the job writer has stopped",
        ));
    }
    Ok(Json(Health { status: "ok", role: app.cluster.as_ref().map(|n| n.role_name()) }))
}

/// Any path no route serves.
pub async fn not_found(method: Method, uri: Uri) -> ApiError {
    ApiError::not_found(format!("no route for {method} {}", uri.path()))
}

/// A known path with a method it does not serve.
pub async fn method_not_allowed(method: Method, uri: Uri) -> ApiError {
    ApiError::new(
        axum::http::StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        format!("{method} is not allowed on {}", uri.path()),
    )
}

/// Middleware: counts every request by method, matched route and status.
///
/// Every label has a bounded set of values, whatever clients send, since this counts
/// requests before any key is checked: the method is one of RFC 9110's eight or PATCH, or
/// `other` ([`method_label`]); the route the matched template or `unmatched` (never the raw
/// path); the status the one sent.
pub async fn count_requests(State(app): State<AppState>, req: Request, next: Next) -> Response {
    let method = method_label(req.method());
    let route = req.extensions().get::<MatchedPath>().map_or("unmatched", |p| p.as_str()).to_owned();
    let response = next.run(req).await;
    app.metrics.count_request(method, route, response.status().as_u16());
    response
}

/// The method as the request counter labels it: the standard methods by name, any other
/// (`curl -X AAAA1`, an extension method) as `other`, so that no client can add label sets.
pub fn method_label(method: &Method) -> &'static str {
    match *method {
        Method::GET => "GET",
        Method::HEAD => "HEAD",
        Method::POST => "POST",
        Method::PUT => "PUT",
        Method::PATCH => "PATCH",
        Method::DELETE => "DELETE",
        Method::OPTIONS => "OPTIONS",
        Method::CONNECT => "CONNECT",
        Method::TRACE => "TRACE",
        _ => "other",
    }
}

/// `GET /metrics`: every family (see [`super::metrics`]), in the format `Accept` asks for.
pub async fn metrics(State(app): State<AppState>, headers: HeaderMap) -> Result<Response, ApiError> {
    use super::metrics::{format::Format, scrape::Scrape};
    let format = Format::negotiate(headers.get(header::ACCEPT));
    let scrape = Scrape {
        devices: crate::service::monitor::all_shown(&app.devices(), app.dispatcher.queues()),
        counts: app.metrics.counts(),
        now: crate::domain::time::now(),
        started: app.metrics.started(),
        cluster: app.cluster.as_ref().map(|n| {
            // One read of the role, so that `active` and `epoch` tell of the same moment.
            let epoch = n.role().epoch();
            super::metrics::scrape::ClusterSample {
                node: n.name.clone(),
                active: epoch.is_some(),
                epoch: epoch.unwrap_or(0),
                takeovers: n.takeovers(),
            }
        }),
        webhooks: webhook_samples(&app),
        orders: app.dispatcher.queues().orders(),
        certificate: app.metrics.certificate(),
    };
    let body = app.metrics.render(scrape, app.hub.subscribers(), format)?;
    Ok(([(header::CONTENT_TYPE, format.content_type())], body).into_response())
}

/// Each running webhook subscription's figures; none on a node that does not deliver them.
fn webhook_samples(app: &AppState) -> Vec<super::metrics::scrape::WebhookSample> {
    let Some(webhooks) = app.webhooks.get() else { return Vec::new() };
    let published = app.hub.published().get();
    let sample = |(config, live): (crate::config::WebhookConfig, _)| super::metrics::scrape::WebhookSample {
        name: config.name,
        published,
        live,
    };
    webhooks.live().into_iter().map(sample).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn methods_outside_the_standard_set_are_other() {
        assert_eq!(method_label(&Method::GET), "GET");
        assert_eq!(method_label(&Method::PATCH), "PATCH");
        assert_eq!(method_label(&Method::TRACE), "TRACE");
        for odd in ["AAAA1", "PROPFIND", "get", "BREW"] {
            assert_eq!(method_label(&Method::from_bytes(odd.as_bytes()).unwrap()), "other", "{odd}");
        }
    }
}
