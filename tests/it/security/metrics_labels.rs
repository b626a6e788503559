//! The request counter is kept before any key is checked, so its label sets must be bounded
//! whatever a stranger sends: 10,000 requests with 10,000 made-up methods and no key leave a
//! handful of `rackd_http_requests` series, not 10,000 more.

use futures::StreamExt;
use rackd::auth::{KeyHash, Role};
use rackd::config::KeyConfig;
use rackd::store::Engine;

use crate::support::spawn_with;

const KEY: &str = "rk_security-metrics-viewer";

#[tokio::test]
async fn ten_thousand_made_up_methods_without_a_key_leave_the_series_bounded() {
    let app = spawn_with(Engine::Sqlite, |c| {
        c.auth.keys = vec![KeyConfig { name: "scraper".into(), role: Role::Viewer, hash: KeyHash::of(KEY) }];
    })
    .await;
    let statuses = futures::stream::iter(0..10_000)
        .map(|i| {
            let method = reqwest::Method::from_bytes(format!("AAAA{i}").as_bytes()).unwrap();
            let request = app.client.request(method, app.url("/api/v1/jobs"));
            async move { request.send().await.unwrap().status().as_u16() }
        })
        .buffer_unordered(16)
        .collect::<Vec<u16>>()
        .await;
    assert!(statuses.iter().all(|s| *s == 401), "no key: 401 for every method");

    let metrics = app.client.get(app.url("/metrics")).bearer_auth(KEY).send().await.unwrap();
    assert_eq!(metrics.status(), 200);
    let text = metrics.text().await.unwrap();
    let series: Vec<&str> = text.lines().filter(|l| l.starts_with("rackd_http_requests_total{")).collect();
    assert!(series.len() <= 4, "the series stay a small constant: {series:#?}");
    let flood = series
        .iter()
        .find(|l| l.contains("method=\"other\"") && l.contains("route=\"/api/v1/jobs\""))
        .unwrap_or_else(|| panic!("the made-up methods are counted as `other`: {series:#?}"));
    assert!(flood.contains("status=\"401\"") && flood.ends_with(" 10000"), "{flood}");
    app.stop().await;
}
