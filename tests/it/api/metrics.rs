//! `/metrics` read by real Prometheus parsers (the Python `prometheus_client` package: its
//! 0.0.4 parser and its strict OpenMetrics parser), with one shelf PLC that answers (the
//! simulator over UDP) and one that does not (a UDP socket nobody reads).

use std::collections::BTreeMap;
use std::time::Duration;

use rackd::sim::shelf::{ShelfSim, ShelfSimOptions};
use rackd::store::Engine;
use serde_json::Value;

use crate::support::eventually;
use crate::support::python::python_with;
use crate::support::{TestApp, spawn_with, store, wait_ended};

const OPENMETRICS_ACCEPT: &str = "application/openmetrics-text;version=1.0.0;q=0.5,\
                                  application/openmetrics-text;version=0.0.1;q=0.4,\
                                  text/plain;version=0.0.4;q=0.3,*/*;q=0.2";

/// Parses stdin with one of prometheus_client's parsers (argv[1]: `openmetrics` or `0.0.4`)
/// and prints the families as JSON: name -> {type, samples: [[name, labels, value]]}.
const PARSE: &str = r#"
import json, sys
if sys.argv[1] == "openmetrics":
    from prometheus_client.openmetrics.parser import text_string_to_metric_families
else:
    from prometheus_client.parser import text_string_to_metric_families
out = {}
for f in text_string_to_metric_families(sys.stdin.read()):
    if f.name in out:
        raise SystemExit("family %s twice" % f.name)
    out[f.name] = {"type": f.type, "samples": [[s.name, s.labels, s.value] for s in f.samples]}
print(json.dumps(out))
"#;

/// The families of `text` as the parser for `format` reads them; fails on a parse error.
pub fn parse(text: &str, format: &str) -> BTreeMap<String, Value> {
    use std::io::Write;
    let mut child = std::process::Command::new(python_with("prometheus_client", "to parse /metrics"))
        .args(["-c", PARSE, format])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(text.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "the {format} parser refused:\n{}\n{text}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The value of the sample `name` with exactly these labels (plus `le` for buckets).
pub fn sample(families: &BTreeMap<String, Value>, name: &str, labels: &[(&str, &str)]) -> Option<f64> {
    families.values().flat_map(|f| f["samples"].as_array().unwrap()).find_map(|s| {
        let got = s[1].as_object().unwrap();
        let same = s[0] == name
            && got.len() == labels.len()
            && labels.iter().all(|(k, v)| got.get(*k).and_then(Value::as_str) == Some(*v));
        same.then(|| s[2].as_f64().unwrap())
    })
}

fn kind(families: &BTreeMap<String, Value>, name: &str) -> String {
    families.get(name).map_or_else(|| format!("no family {name}"), |f| f["type"].as_str().unwrap().to_owned())
}

async fn scrape(app: &TestApp, accept: Option<&str>) -> (String, String) {
    let mut request = app.client.get(app.url("/metrics"));
    if let Some(accept) = accept {
        request = request.header("accept", accept);
    }
    let r = request.send().await.unwrap();
    assert_eq!(r.status(), 200);
    let content_type = r.headers()["content-type"].to_str().unwrap().to_owned();
    (content_type, r.text().await.unwrap())
}

/// Scrapes (0.0.4) until `ready` holds for the parsed families, for at most `secs` seconds.
async fn scrape_until(
    app: &TestApp,
    secs: u64,
    what: &str,
    ready: impl Fn(&BTreeMap<String, Value>) -> bool,
) -> BTreeMap<String, Value> {
    eventually(what, Duration::from_secs(secs), async || {
        let families = parse(&scrape(app, None).await.1, "0.0.4");
        if ready(&families) { Ok(families) } else { Err(families) }
    })
    .await
}

#[tokio::test]
async fn both_formats_parse_with_their_types_and_show_devices_alarms_and_jobs() {
    let sim = ShelfSim::start("127.0.0.1:0", ShelfSimOptions::default()).await.unwrap();
    let silent = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let device = |id: &str, address: String, aisle: u16| {
        let mut d = rackd::cli::demo::shelf_device(&sim, id, &address, vec![aisle]);
        d.poll_ms = 20;
        d.link.timeout = Duration::from_millis(50);
        d.link.retries = 1;
        d
    };
    let online = device("shelf1", sim.local_addr().unwrap().to_string(), 1);
    let offline = device("shelf2", silent.local_addr().unwrap().to_string(), 2);
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![online.into(), offline.into()]).await;
    let (status, job) = app.post("/api/v1/jobs", &store("M1")).await;
    assert_eq!(status, 201, "{job}");
    let jobs = wait_ended(&app, 1, 20).await;
    assert_eq!(jobs[0]["state"], "completed", "{jobs:?}");

    let shelf1 = [("device", "shelf1")];
    let shelf2 = [("device", "shelf2")];
    let link_alarm = [("device", "shelf2"), ("class", "link")];
    // The writer times a job once its group has committed, a moment after the job reads as
    // ended: wait for that too.
    let ended = [("kind", "store"), ("state", "completed")];
    let what = "shelf2 offline with its link alarm, and the job timed";
    let families = scrape_until(&app, 20, what, |f| {
        sample(f, "rackd_device_online", &shelf2) == Some(0.0)
            && sample(f, "rackd_alarms_active", &link_alarm) == Some(1.0)
            && sample(f, "rackd_device_online", &shelf1) == Some(1.0)
            && sample(f, "rackd_job_duration_seconds_count", &ended).is_some()
            // Read apart from the timings in one scrape (the counts first): a commit between
            // the two shows one without the other.
            && sample(f, "rackd_jobs", &[("device", "shelf1"), ("state", "completed")]) == Some(1.0)
    })
    .await;

    // Prometheus text 0.0.4: its content type, no OpenMetrics-only lines, every family typed.
    let (content_type, text) = scrape(&app, None).await;
    assert_eq!(content_type, "text/plain; version=0.0.4; charset=utf-8");
    assert!(!text.contains("# EOF") && !text.contains("# UNIT") && !text.contains(" info\n"), "{text}");
    let untyped: Vec<&String> =
        families.iter().filter(|(_, f)| f["type"] == "untyped").map(|(n, _)| n).collect();
    assert!(untyped.is_empty(), "untyped families in 0.0.4: {untyped:?}\n{text}");
    for (name, want) in [
        ("rackd_http_requests", "counter"),
        ("rackd_jobs", "gauge"),
        ("rackd_intake_seconds", "histogram"),
        ("rackd_build_info", "gauge"),
        ("rackd_device_info", "gauge"),
        ("rackd_device_online", "gauge"),
        ("rackd_device_degraded", "gauge"),
        ("rackd_device_paused", "gauge"),
        ("rackd_device_seconds_since_contact", "gauge"),
        ("rackd_device_link_requests", "counter"),
        ("rackd_device_link_retries", "counter"),
        ("rackd_device_link_timeouts", "counter"),
        ("rackd_device_link_dropped_replies", "counter"),
        ("rackd_device_link_round_trip_seconds", "histogram"),
        ("rackd_alarms_active", "gauge"),
        ("rackd_job_dispatch_seconds", "histogram"),
        ("rackd_job_duration_seconds", "histogram"),
        ("rackd_ws_subscribers", "gauge"),
        ("rackd_ws_resyncs", "counter"),
        ("rackd_ws_snapshots", "counter"),
        ("rackd_writer_group_size", "histogram"),
        ("rackd_writer_commit_seconds", "histogram"),
        ("process_cpu_seconds", "counter"),
        ("process_resident_memory_bytes", "gauge"),
        ("process_open_fds", "gauge"),
        ("process_start_time_seconds", "gauge"),
    ] {
        assert_eq!(kind(&families, name), want, "{name} in 0.0.4:\n{text}");
    }

    // The devices, the alarm and the job.
    assert_eq!(sample(&families, "rackd_device_paused", &shelf1), Some(0.0));
    assert_eq!(
        sample(&families, "rackd_alarms_active", &[("device", "shelf1"), ("class", "link")]),
        Some(0.0)
    );
    let info = [("device", "shelf2"), ("kind", "shelf"), ("protocol", "modbus-udp")];
    let address = silent.local_addr().unwrap().to_string();
    let info: Vec<(&str, &str)> = info.into_iter().chain([("address", address.as_str())]).collect();
    assert_eq!(sample(&families, "rackd_device_info", &info), Some(1.0));
    assert!(sample(&families, "rackd_device_link_round_trip_seconds_count", &shelf1).unwrap() > 0.0);
    assert!(sample(&families, "rackd_device_seconds_since_contact", &shelf1).unwrap() < 5.0);
    let completed = [("device", "shelf1"), ("state", "completed")];
    assert_eq!(sample(&families, "rackd_jobs", &completed), Some(1.0));
    assert_eq!(sample(&families, "rackd_jobs", &[("device", "shelf2"), ("state", "queued")]), Some(0.0));
    assert_eq!(sample(&families, "rackd_job_dispatch_seconds_count", &[("kind", "store")]), Some(1.0));
    assert_eq!(sample(&families, "rackd_job_duration_seconds_count", &ended), Some(1.0));
    assert!(
        sample(&families, "rackd_writer_group_size_count", &[]).unwrap() >= 3.0,
        "accepted, dispatched, ended"
    );
    let version = [
        ("version", env!("CARGO_PKG_VERSION")),
        ("os", std::env::consts::OS),
        ("arch", std::env::consts::ARCH),
    ];
    assert_eq!(sample(&families, "rackd_build_info", &version), Some(1.0));

    // The offline device's timeouts keep counting up.
    let timeouts = sample(&families, "rackd_device_link_timeouts_total", &shelf2).unwrap();
    assert!(timeouts >= 2.0, "{timeouts}");
    scrape_until(&app, 10, "more timeouts on shelf2", |f| {
        sample(f, "rackd_device_link_timeouts_total", &shelf2).is_some_and(|n| n > timeouts)
    })
    .await;

    // OpenMetrics when asked, read by the strict parser, with its own types.
    let (content_type, text) = scrape(&app, Some(OPENMETRICS_ACCEPT)).await;
    assert_eq!(content_type, "application/openmetrics-text; version=1.0.0; charset=utf-8");
    assert!(text.ends_with("# EOF\n"), "{text}");
    let families = parse(&text, "openmetrics");
    for (name, want) in [
        ("rackd_build", "info"),
        ("rackd_device", "info"),
        ("rackd_http_requests", "counter"),
        ("rackd_device_link_timeouts", "counter"),
        ("rackd_device_online", "gauge"),
        ("rackd_device_link_round_trip_seconds", "histogram"),
        ("rackd_job_duration_seconds", "histogram"),
        ("process_cpu_seconds", "counter"),
    ] {
        assert_eq!(kind(&families, name), want, "{name} in OpenMetrics:\n{text}");
    }
    assert_eq!(sample(&families, "rackd_device_online", &shelf2), Some(0.0));
    assert_eq!(sample(&families, "rackd_alarms_active", &link_alarm), Some(1.0));
    app.stop().await;
    drop(silent);
}

#[tokio::test]
async fn a_webhook_that_cannot_deliver_shows_its_failures_and_lag() {
    let app = spawn_with(Engine::Sqlite, |c| {
        // Nothing listens on the discard port: every try fails at once.
        let secret = "whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw";
        let mut wms = rackd::config::WebhookConfig::new("wms", "http://127.0.0.1:9/", &["job.*"], secret);
        (wms.backoff_ms, wms.max_backoff_ms, wms.timeout_ms) = (20, 50, 200);
        c.webhooks = vec![wms];
    })
    .await;
    let wms = [("webhook", "wms")];
    let outcome = |o| [("webhook", "wms"), ("outcome", o)];
    let families = scrape_until(&app, 10, "the subscription's families, caught up", |f| {
        sample(f, "rackd_webhook_paused", &wms).is_some()
    })
    .await;
    assert_eq!(sample(&families, "rackd_webhook_events_behind", &wms), Some(0.0));
    assert_eq!(sample(&families, "rackd_webhook_seconds_behind", &wms), Some(0.0));
    for o in ["delivered", "failed", "gone"] {
        assert_eq!(sample(&families, "rackd_webhook_deliveries_total", &outcome(o)), Some(0.0), "{o}");
    }

    let (status, job) = app.post("/api/v1/jobs", &store("W1")).await;
    assert_eq!(status, 201, "{job}");
    let families = scrape_until(&app, 10, "a failed try and the job's events behind", |f| {
        sample(f, "rackd_webhook_deliveries_total", &outcome("failed")).is_some_and(|n| n >= 1.0)
            && sample(f, "rackd_webhook_events_behind", &wms).is_some_and(|n| n >= 1.0)
    })
    .await;
    let failed = sample(&families, "rackd_webhook_deliveries_total", &outcome("failed")).unwrap();
    assert_eq!(sample(&families, "rackd_webhook_deliveries_total", &outcome("delivered")), Some(0.0));
    assert_eq!(sample(&families, "rackd_webhook_paused", &wms), Some(0.0));
    for (name, want) in [
        ("rackd_webhook_events_behind", "gauge"),
        ("rackd_webhook_seconds_behind", "gauge"),
        ("rackd_webhook_deliveries", "counter"),
        ("rackd_webhook_retries", "counter"),
        ("rackd_webhook_paused", "gauge"),
    ] {
        assert_eq!(kind(&families, name), want, "{name} in 0.0.4");
    }
    // It keeps trying (with backoff), the retries and the age of the event growing with it.
    scrape_until(&app, 10, "more failed tries, counted as retries, and the event's age", |f| {
        sample(f, "rackd_webhook_deliveries_total", &outcome("failed")).is_some_and(|n| n > failed)
            && sample(f, "rackd_webhook_retries_total", &wms).is_some_and(|n| n >= 1.0)
            && sample(f, "rackd_webhook_seconds_behind", &wms).is_some_and(|s| s > 0.0)
    })
    .await;

    let (_, text) = scrape(&app, Some(OPENMETRICS_ACCEPT)).await;
    let families = parse(&text, "openmetrics");
    assert_eq!(kind(&families, "rackd_webhook_deliveries"), "counter", "{text}");
    assert!(sample(&families, "rackd_webhook_events_behind", &wms).is_some_and(|n| n >= 1.0), "{text}");
    app.stop().await;
}
