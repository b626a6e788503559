//! The operator dashboard at `/`: one page and its script and style, compiled into the
//! binary (factories are often offline: no CDN, nothing fetched from elsewhere).
//!
//! The page itself needs no key; it asks for one when the API answers 401 and keeps it in
//! the browser's local storage, then follows the store live through `GET /api/v1/ws`.

use axum::Router;
use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::get;

/// The dashboard's files.
pub fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    Router::new()
        .route("/", get(|| file("text/html; charset=utf-8", include_str!("index.html"))))
        .route("/dashboard.js", get(|| file("text/javascript; charset=utf-8", include_str!("dashboard.js"))))
        .route("/dashboard.css", get(|| file("text/css; charset=utf-8", include_str!("dashboard.css"))))
}

async fn file(content_type: &'static str, body: &'static str) -> impl IntoResponse {
    ([(header::CONTENT_TYPE, content_type), (header::CACHE_CONTROL, "no-cache")], body)
}
