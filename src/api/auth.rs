//! The API key check: who is calling, and may they?
//!
//! The role a request needs follows from its method: reads (`GET`, `HEAD`) need `viewer`,
//! everything else `operator`; routes registered under [`admin_paths`] need `admin`, except
//! pause, resume and tag writes (`/api/v1/devices/{id}/tags/{tag}`), which are operators'
//! daily work. With no
//! keys configured every request is let through (the server then only listens on loopback,
//! see [`crate::app`]).

use std::borrow::Cow;

use axum::extract::{Request, State};
use axum::http::{Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::Response;

use super::error::ApiError;
use super::state::AppState;
use crate::auth::Role;

/// Path prefixes (under `/api/v1`) whose writes are admin only.
pub fn admin_paths() -> &'static [&'static str] {
    &["/api/v1/devices/", "/api/v1/registers"]
}

/// The role a request needs.
pub fn required_role(method: &Method, path: &str) -> Role {
    if method == Method::GET || method == Method::HEAD {
        Role::Viewer
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

/// The key a request presents: `Authorization: Bearer KEY`, `X-Api-Key: KEY`, or (for
/// browsers opening a WebSocket, which cannot set headers) `?token=KEY`, URL-decoded.
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
    let query = req.uri().query()?;
    form_urlencoded::parse(query.as_bytes()).find(|(k, _)| k == "token").map(|(_, v)| v)
}

/// The request without `token` in its query, so that handlers never see (nor refuse, nor
/// log) a key passed that way.
fn without_token(mut req: Request) -> Request {
    let Some(query) = req.uri().query() else { return req };
    if !form_urlencoded::parse(query.as_bytes()).any(|(k, _)| k == "token") {
        return req;
    }
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

/// Middleware: answers 401 without a known key and 403 when the key's role is too low; a
/// `?token=` is taken out of the query before the request goes on.
pub async fn require_key(
    State(app): State<AppState>,
    req: Request,
    next: Next,
) -> Result<Response, ApiError> {
    if app.keys.is_empty() {
        return Ok(next.run(without_token(req)).await);
    }
    let needed = required_role(req.method(), req.uri().path());
    let Some(key) = presented_key(&req) else {
        return Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "an API key is required (Authorization: Bearer KEY)",
        ));
    };
    let Some(who) = app.keys.identify(&key) else {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_by_method_and_path() {
        assert_eq!(required_role(&Method::GET, "/api/v1/jobs"), Role::Viewer);
        assert_eq!(required_role(&Method::POST, "/api/v1/jobs"), Role::Operator);
        assert_eq!(required_role(&Method::PATCH, "/api/v1/jobs/1"), Role::Operator);
        assert_eq!(required_role(&Method::POST, "/api/v1/devices/shelf1/registers"), Role::Admin);
        assert_eq!(required_role(&Method::PUT, "/api/v1/locations"), Role::Admin);
        assert_eq!(required_role(&Method::POST, "/api/v1/locations/1/1/1/1/1/lock"), Role::Operator);
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

    #[test]
    fn a_token_in_the_query_is_url_decoded() {
        let req = Request::builder()
            .uri("/api/v1/ws?topics=jobs&token=a%2Bb%2Fc%3Dd%25")
            .body(axum::body::Body::empty())
            .unwrap();
        assert_eq!(presented_key(&req).as_deref(), Some("a+b/c=d%"));
    }
}
