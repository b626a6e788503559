//! The HTTP API: routes, OpenAPI, auth, errors.
//!
//! Public without a key: `/healthz`, `/readyz`, `/openapi.json`, `/docs` and the dashboard's
//! files (`/`, which asks for a key itself when keys are configured). Everything under
//! `/api/v1` and `/metrics` needs a key once keys are configured (see [`auth`]).

pub mod access;
pub mod aisles;
pub mod alarms;
pub mod auth;
pub mod bulk;
pub mod cluster;
pub mod config;
pub mod contract;
pub mod control;
pub mod dashboard;
pub mod devices;
pub mod dry_run;
pub mod error;
pub mod extract;
pub mod failures;
pub mod forward;
pub mod health;
pub mod inventory;
pub mod jobs;
pub mod keyless;
pub mod locations;
pub mod metrics;
pub mod ops;
pub mod peer;
pub mod query;
pub mod sequences;
pub mod state;
pub mod stats;
pub mod webhooks;
pub mod whoami;
pub mod ws;

use std::time::Duration;

use axum::error_handling::HandleErrorLayer;
use axum::extract::DefaultBodyLimit;
use axum::http::StatusCode;
use axum::{Router, middleware};
use tower::ServiceBuilder;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::trace::TraceLayer;
use utoipa::openapi::security::{ApiKey, ApiKeyValue, HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;
use utoipa_swagger_ui::SwaggerUi;

pub use error::ApiError;
pub use state::AppState;

/// The OpenAPI document's fixed parts; paths come from the routers.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "rackd",
        description = "rackd is a warehouse control system (WCS). A WMS posts jobs (store, retrieve, move, \
clear, light, travel); rackd stores them durably, runs them on the store's machines and reports their \
progress.\n\nEvery error is JSON `{\"error\": {\"code\", \"message\"}}` with the matching status. \
Authenticate with `Authorization: Bearer KEY` (or `X-Api-Key`); roles: `viewer` reads, `operator` \
also submits and changes jobs, `admin` may do everything. A `201` means the job is on disk.",
        license(name = "MIT OR Apache-2.0"),
    ),
    servers((url = "/", description = "This server")),
    tags(
        (name = "jobs", description = "Submit and follow jobs"),
        (name = "sequences", description = "Jobs that reach their destination in order (a pick order's totes): \
read one, complete it, cancel it, re-prioritise it; members join through `POST /api/v1/jobs` with `sequence`"),
        (name = "devices", description = "The machines: status, pause and resume (of a device or a whole aisle, kept \
across restarts and audited); tags of tag I/O devices"),
        (name = "locations", description = "What rackd knows of each location; location locks"),
        (name = "alarms", description = "Device alarms, active and past: plain text, what to do, the protocol \
detail; acknowledge; export as CSV"),
        (name = "events", description = "Live events over WebSocket (`GET /api/v1/ws`). A subscriber first gets a \
`Snapshot` (or, with `?since=SEQ`, the replay of every later event), then every `Event` as it is committed, in \
`seq` order with no gap and no duplicate. Event types and their `data`: `job.updated` (a `Job`), \
`job.late` (a `Job` that has just passed its `deadline`, once), `sequence.updated` (a sequence's row: \
`name`, `station`, `last`, `cancelled_at`, `created_at`, `updated_at`, in Unix ms; with the `jobs` topic), \
`device.updated` (a `DeviceStatus`), `alarm.raised`, `alarm.cleared` and `alarm.updated` (an `Alarm`; \
updated when acknowledged), `location.updated` (a `LocationState`, with its lock), `audit.recorded` (an \
`AuditEntry`: every audited change but a submission, whose jobs' `job.updated` tell of it), `config.reloaded` (an `Applied`: \
who reloaded, the configuration's hash and load time, what changed). A `job.updated` also comes when only a \
queued job's `waiting` reason changed. A subscriber that falls behind gets a `Resync` and the connection closes with code \
4000: reconnect with `?since=` its `seq`. `?topics=jobs,devices,alarms,locations,audit,config` filters both the \
snapshot and the events. Browsers pass the key as `?token=`."),
        (name = "webhooks", description = "Events pushed to the WMS: signed (Standard Webhooks), at least once, \
in order; each subscription's state, its delivery log, pause, resume and replay (administrators)"),
        (name = "operations", description = "Health, readiness, metrics and the audit log of operator actions"),
    ),
    components(schemas(ws::Snapshot, ws::SnapshotData, ws::Resync, ws::StoreState, crate::service::reload::Applied)),
    modifiers(&Security),
)]
struct ApiDoc;

struct Security;

impl Modify for Security {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
        components.add_security_scheme(
            "api_key",
            SecurityScheme::ApiKey(ApiKey::Header(ApiKeyValue::new("X-Api-Key"))),
        );
        openapi.security = Some(vec![
            utoipa::openapi::security::SecurityRequirement::new("bearer", Vec::<String>::new()),
            utoipa::openapi::security::SecurityRequirement::new("api_key", Vec::<String>::new()),
        ]);
    }
}

/// `/metrics`, documented.
#[utoipa::path(get, path = "/metrics", tag = "operations",
    responses((status = 200, description = "The metrics (docs/operations/metrics.md): \
Prometheus text format 0.0.4 \
(`text/plain; version=0.0.4; charset=utf-8`), or OpenMetrics 1.0.0 (`application/openmetrics-text; version=1.0.0; \
charset=utf-8`) when the `Accept` header asks for it", content(
        (String = "text/plain"),
        (String = "application/openmetrics-text"),
    ))))]
async fn metrics_route(
    state: axum::extract::State<AppState>,
    headers: axum::http::HeaderMap,
) -> Result<axum::response::Response, ApiError> {
    ops::metrics(state, headers).await
}

/// Routes that need a key once keys are configured.
fn protected_routes() -> OpenApiRouter<AppState> {
    let v1 = jobs::router()
        .merge(devices::router())
        .merge(locations::router())
        .merge(bulk::router())
        .merge(inventory::router())
        .merge(alarms::router())
        .merge(aisles::router())
        .merge(control::router())
        .merge(health::router())
        .merge(cluster::router())
        .merge(config::router())
        .merge(stats::router())
        .merge(webhooks::router())
        .merge(sequences::router())
        .merge(whoami::router())
        .merge(ws::router());
    OpenApiRouter::with_openapi(ApiDoc::openapi()).nest("/api/v1", v1).routes(routes!(metrics_route))
}

/// Routes open to anyone (probes).
fn public_routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(ops::healthz)).routes(routes!(ops::readyz))
}

/// The OpenAPI document, as `GET /openapi.json` serves it and `rackd openapi` prints it.
pub fn openapi() -> utoipa::openapi::OpenApi {
    let mut doc = protected_routes().into_openapi();
    doc.merge(public_routes().into_openapi());
    contract::complete(&mut doc);
    doc
}

/// The whole HTTP service.
pub fn router(state: AppState, body_limit: usize, timeout: Duration) -> Router {
    let (protected, mut doc) = protected_routes().split_for_parts();
    let (public, public_doc) = public_routes().split_for_parts();
    doc.merge(public_doc);
    contract::complete(&mut doc);
    // Each operation's query parameters, as the document has them (`query`).
    let known = std::sync::Arc::new(query::Known::of(&doc));
    // The 405 fallback is set before the key check is layered on, so that a wrong method
    // on a protected route is refused for a missing key first.
    // Without keys, the checks that stand in for one (`keyless`) are made there too.
    // A standby forwards what only the active node does, once the key is checked; an
    // unknown query parameter is refused after both.
    let protected = protected
        .method_not_allowed_fallback(ops::method_not_allowed)
        .layer(middleware::from_fn_with_state(known.clone(), query::refuse_unknown))
        .layer(middleware::from_fn_with_state(state.clone(), forward::forward))
        .layer(middleware::from_fn_with_state(state.clone(), auth::require_key));
    let public = public.layer(middleware::from_fn_with_state(known, query::refuse_unknown));
    Router::new()
        .merge(protected)
        .merge(public)
        // No validator: Swagger UI would otherwise ask validator.swagger.io to fetch our spec,
        // leaking its URL and failing in an offline plant.
        .merge(
            SwaggerUi::new("/docs")
                .url("/openapi.json", doc)
                .config(utoipa_swagger_ui::Config::default().validator_url("none")),
        )
        .merge(dashboard::router())
        .fallback(ops::not_found)
        .method_not_allowed_fallback(ops::method_not_allowed)
        .layer(middleware::from_fn_with_state(state.clone(), ops::count_requests))
        .layer(DefaultBodyLimit::max(body_limit))
        .layer(
            ServiceBuilder::new()
                // Outermost: the line shows the answer the client got, a timeout's or a
                // panic's included.
                .layer(middleware::from_fn(access::log))
                .layer(CatchPanicLayer::custom(|_| {
                    tracing::error!("a handler panicked");
                    axum::response::IntoResponse::into_response(ApiError::new(
                        StatusCode::INTERNAL_SERVER_ERROR,
                        "internal",
                        "internal error",
                    ))
                }))
                // Spans name the path only: a query may carry `?token=KEY`, which must not
                // end up in logs.
                .layer(TraceLayer::new_for_http().make_span_with(|req: &axum::http::Request<_>| {
                    tracing::debug_span!("request", method = %req.method(), path = %req.uri().path())
                }))
                .layer(HandleErrorLayer::new(|_: tower::BoxError| async {
                    ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "timeout", "the request took too long")
                }))
                .timeout(timeout),
        )
        .with_state(state)
}
