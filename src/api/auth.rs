//! The API key check: who is calling, and may they?
//!
//! The role a request needs follows from its method: reads (`GET`, `HEAD`) need `viewer`,
//! everything else `operator`; writes to the webhooks, the inventory (`PUT /locations`) and
//! the configuration (`POST /config/reload`) need `admin`, as do the routes under
//! [`admin_paths`] except pause, resume and tag writes (`/api/v1/devices/{id}/tags/{tag}`), which are operators'
//! daily work. With no keys configured every request with a key's place taken by keyless
//! mode's checks ([`super::keyless`]) is let through (the server then only listens on
//! loopback, see [`crate::app`]).
//!
//! A key is taken from `Authorization: Bearer` or `X-Api-Key`, and from `?token=` on
//! `GET /api/v1/ws` alone (a browser cannot set headers on a WebSocket); a `token`
//! parameter anywhere else is refused (400 `token_in_query`), in both modes. Unknown keys
//! are counted per client address, and an address that sent too many is held off (429,
//! [`super::failures`]).

use std::borrow::Cow;

use axum::extract::{Request, State};
use axum::http::{Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::Response;

use super::error::ApiError;
use super::extract::peer;
use super::state::AppState;
use crate::auth::Role;

/// Path prefixes (under `/api/v1`) whose writes are admin only.
pub fn admin_paths() -> &'static [&'static str] {
    &["/api/v1/devices/", "/api/v1/registers"]
}

/// The role a request needs.
pub fn required_role(method: &Method, path: &str) -> Role {
    if path.ends_with("/capture") && path.starts_with("/api/v1/") {
        // A device's bytes: every value it holds and rackd writes (a device's, an alarm's).
        Role::Operator
    } else if method == Method::GET || method == Method::HEAD {
        Role::Viewer
    } else if path.starts_with("/api/v1/webhooks") {
        // Where the events go and from where: the site's integration, not its operation.
        Role::Admin
    } else if path.starts_with("/api/v1/config/") {
        // The site's configuration: what runs, and where.
        Role::Admin
    } else if method == Method::PUT && path.trim_end_matches('/') == "/api/v1/locations" {
        // The inventory: what the store holds, for commissioning.
        Role::Admin
    } else if admin_paths().iter().any(|p| path.starts_with(p))
        && !path.ends_with("/pause")
        && !path.ends_with("/resume")
        && !is_tag_write(path)
    {
        Role::Admin
    } else {
        Role::Operator
    }
}

/// `/api/v1/devices/{id}/tags/{tag}`: exactly a device, `tags` and a tag name.
fn is_tag_write(path: &str) -> bool {
    let rest = path.strip_prefix("/api/v1/devices/").unwrap_or("");
    matches!(rest.split('/').collect::<Vec<_>>()[..], [id, "tags", tag] if !id.is_empty() && !tag.is_empty())
}

/// The one route that takes a key from the query: browsers cannot set headers on a
/// WebSocket handshake.
const WS: &str = "/api/v1/ws";

/// Whether the request may carry its key as `?token=`: `GET /api/v1/ws` only.
fn token_allowed(req: &Request) -> bool {
    req.method() == Method::GET && req.uri().path() == WS
}

/// Whether the query holds a `token` parameter.
fn has_token(req: &Request) -> bool {
    req.uri().query().is_some_and(|q| form_urlencoded::parse(q.as_bytes()).any(|(k, _)| k == "token"))
}

/// 400 `token_in_query` for a `?token=` anywhere but `GET /api/v1/ws`: a key in a URL ends
/// up in proxy logs, browser history and screenshots, so it is refused outright rather
/// than silently used (or silently dropped, which would leave the caller wondering why
/// its key does nothing).
fn refuse_token(req: &Request) -> Result<(), ApiError> {
    if has_token(req) && !token_allowed(req) {
        return Err(ApiError::bad_request(
            "token_in_query",
            format!(
                "a key is not taken from the query on {} {} (URLs end up in logs and history): send \
                 `Authorization: Bearer KEY`; `?token=` is for `GET {WS}` only, where a browser cannot set headers",
                req.method(),
                req.uri().path()
            ),
        ));
    }
    Ok(())
}

/// The key a request presents: `Authorization: Bearer KEY`, `X-Api-Key: KEY`, or on
/// `GET /api/v1/ws` alone (browsers opening a WebSocket cannot set headers) `?token=KEY`,
/// URL-decoded.
fn presented_key(req: &Request) -> Option<Cow<'_, str>> {
    let headers = req.headers();
    if let Some(v) = headers.get(header::AUTHORIZATION).and_then(|v| v.to_str().ok()) {
        // The scheme is case-insensitive (RFC 9110 11.1): `bearer KEY` is as good.
        let (scheme, key) = v.trim().split_once(' ')?;
        return scheme.eq_ignore_ascii_case("bearer").then(|| Cow::Borrowed(key.trim()));
    }
    if let Some(v) = headers.get("x-api-key").and_then(|v| v.to_str().ok()) {
        return Some(Cow::Borrowed(v.trim()));
    }
    if !token_allowed(req) {
        return None;
    }
    let query = req.uri().query()?;
    form_urlencoded::parse(query.as_bytes()).find(|(k, _)| k == "token").map(|(_, v)| v)
}

/// The request without `token` in its query, so that handlers never see (nor refuse, nor
/// log) a key passed that way.
fn without_token(mut req: Request) -> Request {
    if !has_token(&req) {
        return req;
    }
    let Some(query) = req.uri().query() else { return req };
    let kept: String = form_urlencoded::Serializer::new(String::new())
        .extend_pairs(form_urlencoded::parse(query.as_bytes()).filter(|(k, _)| k != "token"))
        .finish();
    let path = req.uri().path();
    let rebuilt = if kept.is_empty() { path.to_owned() } else { format!("{path}?{kept}") };
    let mut parts = req.uri().clone().into_parts();
    parts.path_and_query = rebuilt.parse().ok();
    if let Ok(uri) = axum::http::Uri::from_parts(parts) {
        *req.uri_mut() = uri;
    }
    req
}

/// Middleware on every keyed route: who is calling, and may they?
///
/// With keys, in this order: 429 `too_many_failures` while the client's address has used up
/// its failed authentications ([`super::failures`]); 400 `token_in_query` for a `?token=`
/// outside `GET /api/v1/ws`; 401 without a known key (an unknown one counts as a failure);
/// 403 when the key's role is too low. Without keys: keyless mode's checks
/// ([`super::keyless`]: 421, 403, 415), then the same 400. A `?token=` is taken out of the
/// query before the request goes on.
pub async fn require_key(
    State(app): State<AppState>,
    req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    // One ring for the whole request: a reload swaps it whole.
    let keys = app.keys();
    if keys.is_empty() {
        app.hosts.check(&req)?;
        refuse_token(&req)?;
        return Ok(next.run(without_token(req)).await);
    }
    let limit = keys.limit();
    let peer = peer(req.extensions());
    if let Some(wait) = peer.and_then(|ip| app.failures.blocked(ip, limit)) {
        return Err(too_many_failures(wait));
    }
    refuse_token(&req)?;
    let needed = required_role(req.method(), req.uri().path());
    let Some(key) = presented_key(&req) else {
        return Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "an API key is required (Authorization: Bearer KEY)",
        ));
    };
    let Some(who) = keys.identify(&key) else {
        if let Some(ip) = peer {
            app.failures.failed(ip, super::failures::fingerprint(&key), limit);
        }
        return Err(ApiError::new(StatusCode::UNAUTHORIZED, "unauthorized", "the API key is not known"));
    };
    if who.role < needed {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "forbidden",
            format!("this needs the {} role; key {:?} is {}", needed.as_str(), who.name, who.role.as_str()),
        ));
    }
    let who = who.clone();
    let mut req = without_token(req);
    req.extensions_mut().insert(who);
    Ok(next.run(req).await)
}

/// 429 for an address that has used up its failed authentications, with `Retry-After`:
/// the whole seconds left of its window, at least 1.
fn too_many_failures(wait: std::time::Duration) -> ApiError {
    let secs = wait.as_secs() + u64::from(wait.subsec_nanos() > 0);
    let secs = secs.max(1);
    ApiError::new(
        StatusCode::TOO_MANY_REQUESTS,
        "too_many_failures",
        format!("too many unknown API keys from this address; try again in {secs} s"),
    )
    .retry_after(secs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_by_method_and_path() {
        assert_eq!(required_role(&Method::GET, "/api/v1/jobs"), Role::Viewer);
        assert_eq!(required_role(&Method::POST, "/api/v1/jobs"), Role::Operator);
        assert_eq!(required_role(&Method::POST, "/api/v1/webhooks/wms/pause"), Role::Admin);
        assert_eq!(required_role(&Method::GET, "/api/v1/webhooks/wms/deliveries"), Role::Viewer);
        assert_eq!(required_role(&Method::PATCH, "/api/v1/jobs/1"), Role::Operator);
        assert_eq!(required_role(&Method::POST, "/api/v1/devices/shelf1/registers"), Role::Admin);
        assert_eq!(required_role(&Method::PUT, "/api/v1/locations"), Role::Admin);
        assert_eq!(required_role(&Method::POST, "/api/v1/config/reload"), Role::Admin);
        // A capture shows every value a machine holds: operators, though it is a GET.
        assert_eq!(required_role(&Method::GET, "/api/v1/devices/shelf1/capture"), Role::Operator);
        assert_eq!(required_role(&Method::GET, "/api/v1/alarms/7/capture"), Role::Operator);
        assert_eq!(required_role(&Method::GET, "/api/v1/devices/shelf1"), Role::Viewer);
        assert_eq!(required_role(&Method::POST, "/api/v1/locations/1/1/1/1/1/lock"), Role::Operator);
        for bulk in ["/api/v1/locations/unlock", "/api/v1/jobs/retry", "/api/v1/jobs/cancel"] {
            assert_eq!(required_role(&Method::POST, bulk), Role::Operator, "{bulk}");
        }
        assert_eq!(required_role(&Method::POST, "/api/v1/devices/shelf1/pause"), Role::Operator);
        assert_eq!(required_role(&Method::POST, "/api/v1/devices/tower1/tags/beacon.red"), Role::Operator);
        assert_eq!(required_role(&Method::GET, "/api/v1/devices/tower1/tags"), Role::Viewer);
        assert_eq!(required_role(&Method::POST, "/api/v1/devices/tower1/tags"), Role::Admin);
        assert_eq!(required_role(&Method::POST, "/api/v1/devices/tower1/tags/a/b"), Role::Admin);
        assert_eq!(required_role(&Method::POST, "/api/v1/devices//tags/x"), Role::Admin);
    }
}

#[cfg(test)]
mod key_tests {
    use super::*;

    fn request(method: &str, uri: &str) -> Request {
        Request::builder().method(method).uri(uri).body(axum::body::Body::empty()).unwrap()
    }

    #[test]
    fn a_token_in_the_query_is_url_decoded() {
        let req = request("GET", "/api/v1/ws?topics=jobs&token=a%2Bb%2Fc%3Dd%25");
        assert_eq!(presented_key(&req).as_deref(), Some("a+b/c=d%"));
        assert!(refuse_token(&req).is_ok());
        assert_eq!(without_token(req).uri().to_string(), "/api/v1/ws?topics=jobs");
    }

    #[test]
    fn a_token_in_the_query_is_for_the_websocket_alone() {
        for (method, uri) in [
            ("GET", "/api/v1/jobs?token=k"),
            ("POST", "/api/v1/jobs/1/cancel?token=k"),
            ("POST", "/api/v1/ws?token=k"),
        ] {
            let req = request(method, uri);
            assert_eq!(presented_key(&req), None, "{method} {uri}");
            assert_eq!(refuse_token(&req).unwrap_err().code, "token_in_query", "{method} {uri}");
        }
        assert!(refuse_token(&request("GET", "/api/v1/jobs?tokens=1&reference=token")).is_ok());
    }
}
