//! rackd's webhooks verified by a receiver that knows nothing of rackd: `receiver.py`, an
//! http.server built on the Standard Webhooks library for Python (`standardwebhooks`,
//! installed by `cargo xtask test` into `.ci/venv`), as a WMS would write it. One
//! subscription gives it the right secret and every job event must verify; another gives
//! a second copy a wrong one and every try must be refused.

use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rackd::config::WebhookConfig;
use rackd::store::Engine;
use serde_json::Value;
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

use super::api::post_job;
use crate::support::python::python_with;
use crate::support::receiver::SECRET;
use crate::support::{TestApp, eventually, spawn_with};

/// Another valid secret (32 bytes), not the one rackd signs the first subscription with.
const WRONG_SECRET: &str = "whsec_C2FVsBQIhrscChlQIMV+b5sSYspob7oD";

/// `receiver.py` running with one secret, and what it printed.
struct PythonReceiver {
    port: u16,
    lines: Arc<Mutex<Vec<String>>>,
    _child: Child,
}

impl PythonReceiver {
    async fn start(secret: &str) -> PythonReceiver {
        let python = python_with("standardwebhooks", "to verify rackd's webhooks as a WMS would");
        let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/it/webhooks/receiver.py");
        let mut child = Command::new(python)
            .args([script, secret])
            .stdout(Stdio::piped())
            .kill_on_drop(true)
            .spawn()
            .unwrap();
        let mut stdout = BufReader::new(child.stdout.take().unwrap()).lines();
        let first = tokio::time::timeout(Duration::from_secs(10), stdout.next_line()).await;
        let port = match first {
            Ok(Ok(Some(line))) => {
                line.parse().unwrap_or_else(|_| panic!("receiver.py's first line: {line:?}"))
            }
            other => panic!("receiver.py printed no port (its stderr is above): {other:?}"),
        };
        let lines = Arc::new(Mutex::new(Vec::new()));
        let sink = lines.clone();
        tokio::spawn(async move {
            while let Ok(Some(line)) = stdout.next_line().await {
                sink.lock().unwrap().push(line);
            }
        });
        PythonReceiver { port, lines, _child: child }
    }

    fn url(&self) -> String {
        format!("http://127.0.0.1:{}/rackd", self.port)
    }

    /// `(seq, type)` of every event it verified, in the order it did.
    fn verified(&self) -> Vec<(i64, String)> {
        let lines = self.lines.lock().unwrap();
        lines
            .iter()
            .filter_map(|l| l.strip_prefix("verified "))
            .map(|l| {
                let (seq, kind) = l.split_once(' ').unwrap();
                (seq.parse().unwrap(), kind.to_owned())
            })
            .collect()
    }

    /// The reason given for every refusal.
    fn rejected(&self) -> Vec<String> {
        let lines = self.lines.lock().unwrap();
        lines.iter().filter_map(|l| l.strip_prefix("rejected ")).map(str::to_owned).collect()
    }
}

/// A `job.*` subscription named `name` to `url`, retrying fast, alarmed only after a minute.
fn subscription(name: &str, url: &str) -> WebhookConfig {
    let mut config = WebhookConfig::new(name, url, &["job.*"], SECRET);
    (config.backoff_ms, config.max_backoff_ms, config.alarm_after_secs) = (20, 100, 60);
    config
}

/// `(seq, type)` of the log's `job.*` events.
async fn job_events(app: &TestApp) -> Vec<(i64, String)> {
    let pool = rackd::store::open(&app.db, Duration::from_secs(5)).await.unwrap();
    let events = rackd::store::events::after(&pool, 0, 100_000).await.unwrap();
    events.into_iter().filter(|e| e.kind.starts_with("job.")).map(|e| (e.seq, e.kind)).collect()
}

async fn webhook(app: &TestApp, name: &str) -> Value {
    let (status, list) = app.get("/api/v1/webhooks").await;
    assert_eq!(status, 200, "{list}");
    list["webhooks"].as_array().unwrap().iter().find(|w| w["name"] == name).cloned().unwrap()
}

async fn deliveries(app: &TestApp, name: &str) -> Vec<Value> {
    let (status, log) = app.get(&format!("/api/v1/webhooks/{name}/deliveries?limit=1000")).await;
    assert_eq!(status, 200, "{log}");
    log["deliveries"].as_array().unwrap().clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_python_standardwebhooks_receiver_verifies_every_event_and_refuses_a_wrong_secret() {
    let wms = PythonReceiver::start(SECRET).await;
    let stranger = PythonReceiver::start(WRONG_SECRET).await;
    let configs = vec![subscription("wms", &wms.url()), subscription("stranger", &stranger.url())];
    let app = spawn_with(Engine::Sqlite, |c| c.webhooks = configs).await;
    for n in 0..5 {
        post_job(&app, n).await;
    }

    let w = eventually("the wms subscription to catch up", Duration::from_secs(20), async || {
        let w = webhook(&app, "wms").await;
        if w["state"] == "caught_up" { Ok(w) } else { Err(w) }
    })
    .await;
    let wanted = job_events(&app).await;
    assert_eq!(wanted.len(), 5, "one job.updated per queued job: {wanted:?}");
    assert_eq!(w["cursor"].as_i64(), wanted.last().map(|e| e.0), "{w}");
    // Each line is printed before its answer is sent, but read here by another task.
    eventually("receiver.py to tell of every job event", Duration::from_secs(5), async || {
        let verified = wms.verified();
        if verified == wanted { Ok(()) } else { Err(verified) }
    })
    .await;
    assert_eq!(wms.rejected(), Vec::<String>::new(), "the right secret: nothing refused");
    let tries = deliveries(&app, "wms").await;
    assert_eq!(tries.len(), wanted.len(), "one try per event, none failed: {tries:?}");
    assert!(
        tries.iter().all(|d| d["outcome"] == "delivered" && d["status"] == 204),
        "every try delivered, answered 204: {tries:?}"
    );

    // The wrong secret: refused by the library, so rackd retries the first event, failing.
    let tries = eventually("the stranger's refusals", Duration::from_secs(10), async || {
        let tries = deliveries(&app, "stranger").await;
        if tries.len() >= 3 { Ok(tries) } else { Err(tries) }
    })
    .await;
    assert!(
        tries.iter().all(|d| d["outcome"] == "failed" && d["status"] == 400 && d["seq"] == wanted[0].0),
        "every try of the first event failed with 400: {tries:?}"
    );
    let w = webhook(&app, "stranger").await;
    assert_eq!(w["state"], "failing", "{w}");
    assert!(w["last_error"].as_str().unwrap().contains("400"), "{w}");
    assert_eq!(stranger.verified(), Vec::new(), "nothing verifies with the wrong secret");
    let rejected = stranger.rejected();
    assert!(!rejected.is_empty(), "receiver.py saw the tries");
    assert!(
        rejected.iter().all(|r| r == "No matching signature found"),
        "refused for the signature, not the headers or the time: {rejected:?}"
    );
    app.stop().await;
}
