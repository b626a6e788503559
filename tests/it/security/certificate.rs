//! Issue 51, item 10d: a certificate served over HTTPS that expires within 14 days, or a
//! renewal whose files do not load, was a log line and nothing else. It is the
//! `certificate` alarm (device `tls`: code 0 expiring, code 1 the files refused) and two
//! families of `/metrics`, each of which clears once a good certificate is served. Before
//! the fix, no alarm came.

use std::time::Duration;

use serde_json::Value;
use time::OffsetDateTime;

use super::tls::{client, install, spawn_tls};
use crate::api::metrics::{parse, sample};
use crate::support::tls::Ca;
use crate::support::{TestApp, eventually};

/// The active alarms of device `tls`, by code, once `wanted` holds for them.
async fn tls_alarms(app: &TestApp, https: &reqwest::Client, what: &str, wanted: &[i64]) -> Vec<Value> {
    eventually(what, Duration::from_secs(10), async || {
        let url = app.url("/api/v1/alarms?active=true&device=tls");
        let page: Value = https.get(url).send().await.unwrap().json().await.unwrap();
        let alarms = page["alarms"].as_array().unwrap().clone();
        let mut codes: Vec<i64> = alarms.iter().map(|a| a["code"].as_i64().unwrap()).collect();
        codes.sort();
        if codes == wanted { Ok(alarms) } else { Err(page) }
    })
    .await
}

/// The certificate's two samples, as both parsers read `/metrics`: (expiry, reload failing).
async fn certificate_samples(app: &TestApp, https: &reqwest::Client) -> (Option<f64>, Option<f64>) {
    let text = https.get(app.url("/metrics")).send().await.unwrap().text().await.unwrap();
    let families = parse(&text, "0.0.4");
    let expiry = sample(&families, "rackd_tls_certificate_expiry_timestamp_seconds", &[]);
    let failing = sample(&families, "rackd_tls_certificate_reload_failing", &[]);
    let accept = "application/openmetrics-text;version=1.0.0";
    let open = https.get(app.url("/metrics")).header("accept", accept).send().await.unwrap();
    let families = parse(&open.text().await.unwrap(), "openmetrics");
    assert_eq!(sample(&families, "rackd_tls_certificate_expiry_timestamp_seconds", &[]), expiry);
    (expiry, failing)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_expiring_certificate_and_a_renewal_that_does_not_load_are_alarms_and_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let site = Ca::new("Site CA");
    let now = OffsetDateTime::now_utc().replace_nanosecond(0).unwrap();
    let soon = now + time::Duration::days(10);
    let app = spawn_tls(dir.path(), &site.server_until(soon)).await;
    let https = client(&site);

    let alarms = tls_alarms(&app, &https, "the expiry alarm", &[0]).await;
    let text = alarms[0]["text"].as_str().unwrap();
    assert_eq!(alarms[0]["kind"], "certificate", "{alarms:?}");
    assert!(text.contains(&format!("expires on {}", soon.date())) && text.contains("server.crt"), "{text}");
    let expiry = soon.unix_timestamp() as f64;
    assert_eq!(certificate_samples(&app, &https).await, (Some(expiry), Some(0.0)));

    // Half a renewal (the new certificate, the old key): refused, the old one still served.
    let renewed = site.server();
    let (cert_file, new) = (dir.path().join("server.crt"), dir.path().join("server.crt.new"));
    std::fs::write(&new, &renewed.cert_pem).unwrap();
    std::fs::rename(&new, &cert_file).unwrap();
    let alarms = tls_alarms(&app, &https, "the refused files' alarm", &[0, 1]).await;
    let refused = alarms.iter().find(|a| a["code"] == 1).unwrap()["text"].as_str().unwrap().to_owned();
    assert!(refused.contains("do not load") && refused.contains("previous certificate"), "{refused}");
    assert_eq!(certificate_samples(&app, &https).await, (Some(expiry), Some(1.0)));

    // The key comes too: the renewed certificate is served, and both alarms clear.
    install(dir.path(), &renewed);
    tls_alarms(&app, &https, "both alarms cleared", &[]).await;
    let (expiry, failing) = certificate_samples(&app, &https).await;
    assert_eq!(failing, Some(0.0));
    assert!(expiry.unwrap() > (now + time::Duration::days(3650)).unix_timestamp() as f64, "{expiry:?}");
    app.stop().await;
}
