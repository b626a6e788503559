//! The operator dashboard at `/`: one page and its script modules and style, compiled into
//! the binary (factories are often offline: no CDN, nothing fetched from elsewhere).
//!
//! The page itself needs no key; it asks for one when the API answers 401 and keeps it in
//! the browser's local storage, then follows the store live through `GET /api/v1/ws`.
//!
//! The script is a handful of ES modules: `dashboard.js` starts everything; under
//! `/dashboard/`, `api.js` (key and HTTP calls), `live.js` (the WebSocket, reconnection),
//! `model.js` (the state the events build), `dom.js` (element and time helpers), and one
//! module per part of the page: `counters.js` (the header), `attention.js` (the jobs that
//! need a person), `alarms.js` (with `recovery.js`, a memory loss's Unlock and retry),
//! `devices.js`, `racks.js` (with `crane.js`, where a crane is
//! drawn, and `locations.js`, a location's dialog), `kpi.js` (the KPIs, as SVG charts drawn by the page), `jobs.js` (with
//! `actions.js`, the job buttons), `sequences.js` (the sequences under way, from the jobs
//! held), `webhooks.js` (the webhook subscriptions, their lag,
//! last error and delivery log); `reasons.js` says why a job waits, `late.js` how late it is, `config.js` which configuration runs, `cluster.js` which node
//! of a cluster the page talks to, and `roles.js` which
//! buttons the key may use. The style is `dashboard.css` (the page, its header and panels)
//! with `racks.css` and `jobs.css` (the job table, its cards on a tablet, the KPIs).
//!
//! The page is written against the API of issue 14 (a job's `waiting` object,
//! `GET /api/v1/stats`, alarm acknowledgement and export, `GET /api/v1/whoami`) and degrades
//! on a rackd without it: no reason shown, no KPI panel, no Acknowledge or export button,
//! and the role found by a harmless probe (see `roles.js`).

use axum::Router;
use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::get;

const HTML: &str = "text/html; charset=utf-8";
const JS: &str = "text/javascript; charset=utf-8";
const CSS: &str = "text/css; charset=utf-8";
const SVG: &str = "image/svg+xml";

/// Everything the page loads, by path.
const FILES: &[(&str, &str, &str)] = &[
    ("/", HTML, include_str!("index.html")),
    ("/dashboard.css", CSS, include_str!("dashboard.css")),
    ("/dashboard/racks.css", CSS, include_str!("racks.css")),
    ("/dashboard/jobs.css", CSS, include_str!("jobs.css")),
    ("/dashboard.js", JS, include_str!("dashboard.js")),
    ("/dashboard/api.js", JS, include_str!("api.js")),
    ("/dashboard/live.js", JS, include_str!("live.js")),
    ("/dashboard/model.js", JS, include_str!("model.js")),
    ("/dashboard/dom.js", JS, include_str!("dom.js")),
    ("/dashboard/racks.js", JS, include_str!("racks.js")),
    ("/dashboard/crane.js", JS, include_str!("crane.js")),
    ("/dashboard/devices.js", JS, include_str!("devices.js")),
    ("/dashboard/jobs.js", JS, include_str!("jobs.js")),
    ("/dashboard/alarms.js", JS, include_str!("alarms.js")),
    ("/dashboard/recovery.js", JS, include_str!("recovery.js")),
    ("/dashboard/actions.js", JS, include_str!("actions.js")),
    ("/dashboard/attention.js", JS, include_str!("attention.js")),
    ("/dashboard/counters.js", JS, include_str!("counters.js")),
    ("/dashboard/kpi.js", JS, include_str!("kpi.js")),
    ("/dashboard/locations.js", JS, include_str!("locations.js")),
    ("/dashboard/reasons.js", JS, include_str!("reasons.js")),
    ("/dashboard/sequences.js", JS, include_str!("sequences.js")),
    ("/dashboard/late.js", JS, include_str!("late.js")),
    ("/dashboard/roles.js", JS, include_str!("roles.js")),
    ("/dashboard/cluster.js", JS, include_str!("cluster.js")),
    ("/dashboard/config.js", JS, include_str!("config.js")),
    ("/dashboard/webhooks.js", JS, include_str!("webhooks.js")),
    // Browsers ask for /favicon.ico whatever the page says; an SVG answers both.
    ("/favicon.svg", SVG, include_str!("favicon.svg")),
    ("/favicon.ico", SVG, include_str!("favicon.svg")),
];

/// Only this server's own files and WebSocket: data from the WMS (barcodes, references) is
/// shown as text, and this keeps anything that slipped through from loading or running.
const CSP: &str = "default-src 'self'; connect-src 'self' ws: wss:; img-src 'self' data:; \
                   style-src 'self'; script-src 'self'; object-src 'none'; base-uri 'none'; \
                   frame-ancestors 'none'";

/// The dashboard's files.
pub fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    FILES.iter().fold(Router::new(), |router, &(path, content_type, body)| {
        router.route(path, get(move || file(content_type, body)))
    })
}

async fn file(content_type: &'static str, body: &'static str) -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
            (header::CONTENT_SECURITY_POLICY, CSP),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        body,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_module_the_scripts_import_is_served() {
        let served: Vec<&str> = FILES.iter().map(|f| f.0).collect();
        for (path, _, body) in FILES.iter().filter(|f| f.1 == JS) {
            for line in body.lines().filter(|l| l.starts_with("import ")) {
                let name = line.rsplit_once("from '").and_then(|(_, rest)| rest.strip_suffix("';"));
                let name = name.unwrap_or_else(|| panic!("{path}: unexpected import line {line:?}"));
                let dir = if *path == "/dashboard.js" { "/" } else { "/dashboard/" };
                let target = format!("{dir}{}", name.trim_start_matches("./"));
                assert!(served.contains(&target.as_str()), "{path} imports {target}, which is not served");
            }
        }
    }
}
