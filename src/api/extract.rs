//! Extractors whose rejections are [`ApiError`]s, so bad input always gets JSON.

use axum::extract::rejection::{JsonRejection, PathRejection, QueryRejection};
use std::net::{IpAddr, SocketAddr};

use axum::extract::{ConnectInfo, FromRequest, FromRequestParts, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use serde::de::DeserializeOwned;

use super::error::ApiError;
use crate::domain::Who;

/// `axum::Json`, rejecting with [`ApiError`]. Also usable as a response.
///
/// A body sent as plain `application/json` is read with `serde_json` alone first, and only
/// a body it refuses goes through `axum::Json` again, for the rejection (which names where
/// the body went wrong): `axum::Json` tracks that path through every value it reads. Both
/// accept the same bodies. Any other content type (with parameters, `+json`, none) goes
/// to `axum::Json` at once, which accepts or refuses it as before.
pub struct Json<T>(pub T);

impl<T: DeserializeOwned, S: Send + Sync> FromRequest<S> for Json<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        let plain = req
            .headers()
            .get(axum::http::header::CONTENT_TYPE)
            .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"application/json"));
        if !plain {
            return Ok(Json(axum::Json::<T>::from_request(req, state).await?.0));
        }
        let bytes = axum::body::Bytes::from_request(req, state).await.map_err(JsonRejection::from)?;
        match serde_json::from_slice(&bytes) {
            Ok(value) => Ok(Json(value)),
            Err(_) => Ok(Json(axum::Json::<T>::from_bytes(&bytes)?.0)),
        }
    }
}

impl<T: serde::Serialize> IntoResponse for Json<T> {
    fn into_response(self) -> Response {
        axum::Json(self.0).into_response()
    }
}

/// `axum::extract::Path`, rejecting with [`ApiError`].
#[derive(FromRequestParts)]
#[from_request(via(axum::extract::Path), rejection(ApiError))]
pub struct Path<T>(pub T);

/// `axum::extract::Query`, rejecting with [`ApiError`].
#[derive(FromRequestParts)]
#[from_request(via(axum::extract::Query), rejection(ApiError))]
pub struct Query<T>(pub T);

/// A JSON body that may be left out: an empty body (or `null`) is `T::default()`.
pub struct OptionalJson<T>(pub T);

impl<T: DeserializeOwned + Default, S: Send + Sync> FromRequest<S> for OptionalJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        let bytes = axum::body::Bytes::from_request(req, state).await.map_err(|r| {
            if r.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::new(
                    StatusCode::PAYLOAD_TOO_LARGE,
                    "body_too_large",
                    "the request body is too large",
                )
            } else {
                ApiError::bad_request("bad_body", r.body_text())
            }
        })?;
        if bytes.iter().all(u8::is_ascii_whitespace) || bytes.trim_ascii() == b"null" {
            return Ok(OptionalJson(T::default()));
        }
        Ok(OptionalJson(axum::Json::<T>::from_bytes(&bytes)?.0))
    }
}

/// Who sends the request: the name of the API key it presented (`anonymous` when no keys
/// are configured), and the client's address. Audited with every change.
pub struct Caller {
    /// The key's name.
    pub name: String,
    /// The client's address (see [`peer`]), when known.
    pub client: Option<IpAddr>,
}

impl Caller {
    /// The caller, as audited.
    pub fn who(&self) -> Who {
        Who { name: self.name.clone(), client: self.client }
    }
}

impl<S: Send + Sync> FromRequestParts<S> for Caller {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, Self::Rejection> {
        let name = parts.extensions.get::<crate::auth::Principal>().map(|p| p.name.clone());
        Ok(Caller { name: name.unwrap_or_else(|| "anonymous".to_owned()), client: peer(&parts.extensions) })
    }
}

/// The address of the request's TCP peer (an IPv4 address mapped into IPv6 written as
/// IPv4), when the server recorded it (`ConnectInfo`). `X-Forwarded-For` is not read:
/// anyone can send it, and rackd has no list of proxies to trust.
pub fn peer(extensions: &axum::http::Extensions) -> Option<IpAddr> {
    extensions.get::<ConnectInfo<SocketAddr>>().map(|c| c.0.ip().to_canonical())
}

impl From<JsonRejection> for ApiError {
    fn from(r: JsonRejection) -> Self {
        let message = r.body_text();
        match r {
            JsonRejection::MissingJsonContentType(_) => ApiError::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported_media_type",
                "expected a body with `Content-Type: application/json`",
            ),
            JsonRejection::JsonSyntaxError(_) => ApiError::bad_request("malformed_json", message),
            JsonRejection::JsonDataError(_) => ApiError::invalid("invalid_body", message),
            _ if r.status() == StatusCode::PAYLOAD_TOO_LARGE => ApiError::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                "body_too_large",
                "the request body is too large",
            ),
            _ => ApiError::bad_request("bad_body", message),
        }
    }
}

impl From<PathRejection> for ApiError {
    fn from(r: PathRejection) -> Self {
        ApiError::bad_request("bad_path", r.body_text())
    }
}

impl From<QueryRejection> for ApiError {
    fn from(r: QueryRejection) -> Self {
        ApiError::bad_request("bad_query", r.body_text())
    }
}

/// A page's size (`limit`, 1..=1000, default 100) and where it starts (`cursor`: an id this
/// server gave, at least `min_id`), from a list's query.
pub fn page(limit: Option<u32>, cursor: Option<String>, min_id: i64) -> Result<(u32, Option<i64>), ApiError> {
    let limit = limit.unwrap_or(100);
    if !(1..=1000).contains(&limit) {
        return Err(ApiError::bad_request("bad_query", format!("limit must be 1..=1000, got {limit}")));
    }
    let at = cursor
        .map(|c| {
            c.parse::<i64>().ok().filter(|&id| id >= min_id).ok_or_else(|| {
                ApiError::bad_request("bad_cursor", format!("cursor {c:?} is not one this server gave"))
            })
        })
        .transpose()?;
    Ok((limit, at))
}
