//! On a standby node of a cluster, what only the active node can do is forwarded to it:
//! everything about devices and aisles (their status lives in the active node's device
//! tasks; a pause acts on its dispatcher), and every change to a job or location after
//! its submission (cancel, retry, priority, locks, the inventory), since the active
//! node's dispatcher decides on those against what it holds in memory. Submissions and
//! every read of the store are served by the standby itself (a submission reaches the
//! active node through the database's notifications).
//!
//! The active node is found from the lease row and the address it tells
//! (`[cluster] url`); the request goes on with its method, path, query, body and
//! headers (the key included: the active node checks it again), marked with
//! `x-rackd-forwarded-by`. A forwarded request is never forwarded again: a node that is
//! standby itself by then answers 503, as does a standby that finds no active node (a
//! takeover in progress); the client tries again.

use std::sync::LazyLock;
use std::time::Duration;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{HeaderName, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use super::state::AppState;
use crate::service::cluster::Role;

/// Marks a forwarded request, with the name of the node that forwarded it.
pub const FORWARDED_BY: HeaderName = HeaderName::from_static("x-rackd-forwarded-by");

/// Largest body forwarded (the API's own limit is checked again by the active node).
const MOST: usize = 16 * 1024 * 1024;

static CLIENT: LazyLock<reqwest::Client> = LazyLock::new(|| {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(30))
        .connect_timeout(Duration::from_secs(2))
        .build()
        .unwrap_or_default()
});

/// Whether only the active node serves `method` on `path`.
pub fn only_active(method: &Method, path: &str) -> bool {
    let Some(p) = path.strip_prefix("/api/v1/") else { return false };
    let under = |prefix: &str| p == prefix || p.starts_with(&format!("{prefix}/"));
    under("devices")
        || under("aisles")
        || p == "health"
        || (method != Method::GET && p.starts_with("jobs/") && p != "jobs/batch")
        || (method != Method::GET && under("locations"))
}

/// Middleware: forwards what only the active node does, on a standby.
pub async fn forward(State(app): State<AppState>, req: Request, next: Next) -> Response {
    let Some(node) = &app.cluster else { return next.run(req).await };
    if node.role() != Role::Standby || !only_active(req.method(), req.uri().path()) {
        return next.run(req).await;
    }
    if req.headers().contains_key(&FORWARDED_BY) {
        return unavailable(
            "the request was forwarded to this node, which no longer drives the machines; try again",
        );
    }
    let active = match node.active().await {
        Ok(Some(active)) => active,
        Ok(None) => {
            return unavailable(
                "no node drives the machines at the moment (a takeover is under way); try again",
            );
        }
        Err(e) => {
            tracing::warn!(error = %e, "cluster: the active node cannot be looked up");
            return unavailable("the cluster's database does not answer; try again");
        }
    };
    let (parts, body) = req.into_parts();
    let Ok(body) = axum::body::to_bytes(body, MOST).await else {
        let message = format!("a body to forward is at most {MOST} bytes");
        return ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, "body_too_large", message).into_response();
    };
    match send(&active.url, &node.name, parts, body).await {
        Ok(response) => response,
        Err(e) => {
            tracing::warn!(error = %e, active = %active.name, url = %active.url, "cluster: forwarding failed");
            unavailable(&format!("the active node {:?} cannot be reached; try again", active.name))
        }
    }
}

async fn send(
    base: &str,
    me: &str,
    parts: axum::http::request::Parts,
    body: axum::body::Bytes,
) -> Result<Response, reqwest::Error> {
    let path = parts.uri.path_and_query().map_or("/", |p| p.as_str());
    let url = format!("{}{path}", base.trim_end_matches('/'));
    let mut out = CLIENT.request(parts.method, url).body(body);
    for (name, value) in &parts.headers {
        if name != header::HOST && name != header::CONTENT_LENGTH && name != header::CONNECTION {
            out = out.header(name, value);
        }
    }
    let answer = out.header(FORWARDED_BY, me).send().await?;
    let status = answer.status();
    let mut response = Response::builder().status(status.as_u16());
    for (name, value) in answer.headers() {
        if name != header::CONTENT_LENGTH && name != header::CONNECTION && name != header::TRANSFER_ENCODING {
            response = response.header(name, value);
        }
    }
    let bytes = answer.bytes().await?;
    Ok(response
        .body(Body::from(bytes))
        .unwrap_or_else(|_| unavailable("the active node's answer was malformed")))
}

fn unavailable(message: &str) -> Response {
    ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_only_the_active_node_does() {
        for (method, path) in [
            (Method::GET, "/api/v1/devices"),
            (Method::POST, "/api/v1/devices/crane1/pause"),
            (Method::GET, "/api/v1/aisles/2"),
            (Method::GET, "/api/v1/health"),
            (Method::POST, "/api/v1/jobs/7/cancel"),
            (Method::PATCH, "/api/v1/jobs/7"),
            (Method::PUT, "/api/v1/locations"),
            (Method::POST, "/api/v1/locations/1/1/1/1/1/lock"),
        ] {
            assert!(only_active(&method, path), "{method} {path}");
        }
        for (method, path) in [
            (Method::POST, "/api/v1/jobs"),
            (Method::POST, "/api/v1/jobs/batch"),
            (Method::GET, "/api/v1/jobs/7"),
            (Method::GET, "/api/v1/locations"),
            (Method::POST, "/api/v1/alarms/3/acknowledge"),
            (Method::GET, "/api/v1/ws"),
            (Method::GET, "/readyz"),
            (Method::GET, "/api/v1/devicesx"),
        ] {
            assert!(!only_active(&method, path), "{method} {path}");
        }
    }
}
