//! On a standby node of a cluster, what only the active node can do is forwarded to it:
//! everything about devices and aisles (their status lives in the active node's device
//! tasks; a pause acts on its dispatcher), and every change to a job or location after
//! its submission (cancel, retry, priority, locks, the inventory, the bulk actions on many
//! of them), since the active node's dispatcher decides on those against what it holds in
//! memory. Submissions and every read of the store are served by the standby itself (a
//! submission reaches the active node through the database's notifications).
//!
//! The active node is found from the lease row and the address it tells
//! (`[cluster] url`); the request goes on with its method, path, query, body and
//! headers (the key included: the active node checks it again), marked with
//! `x-rackd-forwarded-by`. A forwarded request is never forwarded again: a node that is
//! standby itself by then answers 503, as does a standby that finds no active node (a
//! takeover in progress); the client tries again.
//!
//! The link between nodes carries the callers' keys, so ([`super::peer::Forwarder`]):
//! - **no proxy**: the client ignores `HTTP_PROXY` and the like; nodes of one cluster talk
//!   to each other directly, and a proxy named in a service's environment for its other
//!   traffic must not see the keys.
//! - **https** when the active node's `[cluster] url` says so, trusting `[cluster] ca_file`
//!   alone when it is set, otherwise the public roots compiled into the binary
//!   (webpki-roots). Those rather than the system's store (rustls-native-certs): sqlx and
//!   reqwest already bring webpki-roots, so they cost nothing more, and they behave the
//!   same in a slim container without a CA bundle; a site's own CA is what `ca_file` is for.
//! - **plain http to another machine, with keys configured**: forwarded, with a warning
//!   logged once per process (and at startup for the node's own `cluster.url`), not
//!   refused: a cluster on a segregated plant network may choose it, and refusing would stop
//!   a working cluster at an upgrade. docs/operations/standby.md says how to move to https.
//! - **no redirects** followed: a key is never sent on to where an answer points.
//! - **the API's body limit** (`server.body_limit_bytes`): a body is buffered up to it and
//!   no further; a larger one is answered 413 here, as the standby's own routes would. The
//!   active node's answer is streamed back as it comes, never held whole.
//! - **no key in a URL**: the key check refuses `?token=` on every route but the WebSocket
//!   (400 `token_in_query`) before anything is forwarded, and the WebSocket is not
//!   forwarded (each node streams its own events), so a key only ever travels in a header.
//! - **`Origin` is not passed on**: this node checked it already (without keys, see
//!   `api::keyless`), against its own names; the active node, whose names differ, would
//!   refuse the dashboard of this node. A browser cannot send `x-rackd-forwarded-by` to
//!   another site without a preflight, which rackd never grants.

use std::sync::atomic::Ordering;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{HeaderName, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::error::ApiError;
use super::peer::{in_clear, warn_if_clear};
use super::state::AppState;
use crate::service::cluster::Role;

/// Marks a forwarded request, with the name of the node that forwarded it.
pub const FORWARDED_BY: HeaderName = HeaderName::from_static("x-rackd-forwarded-by");

/// Whether only the active node serves `method` on `path`.
pub fn only_active(method: &Method, path: &str) -> bool {
    let Some(p) = path.strip_prefix("/api/v1/") else { return false };
    let under = |prefix: &str| p == prefix || p.starts_with(&format!("{prefix}/"));
    under("devices")
        || (p.starts_with("alarms/") && p.ends_with("/capture"))
        || under("aisles")
        || p == "health"
        || (method != Method::GET && p.starts_with("jobs/") && p != "jobs/batch")
        || (method != Method::GET && under("locations"))
        || (method != Method::GET && under("webhooks"))
        || (method != Method::GET && under("sequences"))
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
    let Some(forwarder) = &app.forwarder else {
        return unavailable("this node cannot forward to the active node; try another node");
    };
    if forwarder.keyed && in_clear(&active.url) && !forwarder.warned.swap(true, Ordering::Relaxed) {
        warn_if_clear(&active.url, true, &format!("the active node {:?}'s cluster.url", active.name));
    }
    let (parts, body) = req.into_parts();
    let Ok(body) = axum::body::to_bytes(body, forwarder.limit).await else {
        let message = format!("the body is over server.body_limit_bytes ({} bytes)", forwarder.limit);
        return ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, "body_too_large", message).into_response();
    };
    match send(&forwarder.client, &active.url, &node.name, parts, body).await {
        Ok(response) => response,
        Err(e) => {
            tracing::warn!(error = %e, active = %active.name, url = crate::redact::url(&active.url), "cluster: forwarding failed");
            unavailable(&format!("the active node {:?} cannot be reached; try again", active.name))
        }
    }
}

async fn send(
    client: &reqwest::Client,
    base: &str,
    me: &str,
    parts: axum::http::request::Parts,
    body: axum::body::Bytes,
) -> Result<Response, reqwest::Error> {
    let path = parts.uri.path_and_query().map_or("/", |p| p.as_str());
    let url = format!("{}{path}", base.trim_end_matches('/'));
    let mut out = client.request(parts.method, url).body(body);
    for (name, value) in &parts.headers {
        let hop = [header::HOST, header::CONTENT_LENGTH, header::CONNECTION, header::ORIGIN];
        if !hop.contains(name) {
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
    // Streamed through, not buffered: an answer (a long device list, say) costs this node
    // no more memory than its chunks in flight.
    Ok(response
        .body(Body::from_stream(answer.bytes_stream()))
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
            (Method::POST, "/api/v1/locations/unlock"),
            (Method::POST, "/api/v1/jobs/retry"),
            (Method::POST, "/api/v1/jobs/cancel"),
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
            // Each node reads and checks its own file (a standby's is kept for its takeover).
            (Method::POST, "/api/v1/config/reload"),
        ] {
            assert!(!only_active(&method, path), "{method} {path}");
        }
    }
}
