//! The log a site reads, from the real binary: an offline device is one warning, not five
//! a second; its return is one line; lines carry the device and job from their spans; every
//! request has an access line without its query.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::{Value, json};

use crate::support::eventually;

/// A child process killed when the test ends, however it ends.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// JSON log lines read from a child's stderr as they come.
#[derive(Clone, Default)]
struct Lines(Arc<Mutex<Vec<Value>>>);

impl Lines {
    fn follow(child: &mut Child) -> Lines {
        let lines = Lines::default();
        let out = lines.clone();
        let stderr = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let value = serde_json::from_str(&line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"));
                out.0.lock().unwrap().push(value);
            }
        });
        lines
    }

    fn matching(&self, f: impl Fn(&Value) -> bool) -> Vec<Value> {
        self.0.lock().unwrap().iter().filter(|l| f(l)).cloned().collect()
    }

    /// Waits (bounded) for a line `f` accepts.
    async fn wait_for(&self, what: &str, f: impl Fn(&Value) -> bool) -> Value {
        eventually(format!("a line {what}"), Duration::from_secs(20), async || {
            self.matching(&f).into_iter().next().ok_or_else(|| format!("{:#?}", self.0.lock().unwrap()))
        })
        .await
    }
}

/// The value of `key` in the span named `span` the line was logged in.
fn span_field<'a>(line: &'a Value, span: &str, key: &str) -> Option<&'a Value> {
    line["spans"].as_array()?.iter().find(|s| s["name"] == span).and_then(|s| s.get(key))
}

fn device_is(line: &Value, id: &str) -> bool {
    span_field(line, "device", "device").is_some_and(|d| d == id)
}

/// A `rackd sim ARGS` child listening where it chooses (`--listen 127.0.0.1:0`), and the
/// address it says it listens on (the first address on its standard output, which is read
/// to the end meanwhile).
fn sim(args: &[&str]) -> (Killed, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .arg("sim")
        .args(args)
        .args(["--listen", "127.0.0.1:0"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let child = Killed(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut said = false;
        for line in lines.map_while(Result::ok) {
            let at = line
                .split_whitespace()
                .find_map(|w| w.trim_end_matches(':').parse::<std::net::SocketAddr>().ok());
            if let (false, Some(at)) = (said, at) {
                said = true;
                let _ = tx.send(at.to_string());
            }
        }
    });
    let at = rx
        .recv_timeout(Duration::from_secs(30))
        .unwrap_or_else(|e| panic!("rackd sim {args:?} said no address: {e}"));
    (child, at)
}

/// Sends `signal` (`-STOP`, `-CONT`) to the process.
fn signal(child: &Killed, signal: &str) {
    let pid = child.0.id().to_string();
    assert!(Command::new("kill").args([signal, &pid]).status().unwrap().success(), "kill {signal} {pid}");
}

async fn wait_http(base: &str) {
    let healthz = format!("{base}/healthz");
    eventually("the server to come up", Duration::from_secs(20), async || reqwest::get(&healthz).await).await;
}

#[tokio::test]
async fn an_offline_device_logs_once_its_return_once_and_requests_one_line_each() {
    let dir = tempfile::tempdir().unwrap();
    // Every process listens where it chooses and says where. The shelf's PLC is stopped
    // (SIGSTOP) as soon as it has said: its port held, nothing answering, until it goes on.
    let (_crane, crane) = sim(&["crane", "--step-ms", "50"]);
    let (shelf_sim, shelf) = sim(&["shelf", "--protocol", "modbus-udp"]);
    signal(&shelf_sim, "-STOP");
    let config = dir.path().join("rackd.toml");
    std::fs::write(
        &config,
        format!(
            r#"
[server]
listen = "127.0.0.1:0"
[database]
path = "{db}"
[[site.aisles]]
aisle = 1
rows = 2
bays = 10
levels = 6
positions = 4
[[site.aisles]]
aisle = 2
rows = 2
bays = 20
levels = 8
positions = 2
[[devices]]
id = "shelf1"
kind = "shelf"
aisles = [1]
protocol = "modbus-udp"
address = "{shelf}"
timeout_ms = 50
retries = 0
poll_ms = 100
[[devices]]
id = "crane1"
kind = "crane"
aisles = [2]
protocol = "mc3e"
address = "{crane}"
"#,
            db = dir.path().join("rackd.db").display()
        ),
    )
    .unwrap();
    let mut server = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["serve", "--config", config.to_str().unwrap()])
        .env("RACKD_LOG_FORMAT", "json")
        .env("RACKD_LOG", "info,rackd::devices::crane=debug")
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lines = Lines::follow(&mut server);
    let _server = Killed(server);
    let listening =
        lines.wait_for("saying where rackd listens", |l| l["fields"]["message"] == "rackd listening").await;
    let base = format!("http://{}", listening["fields"]["addr"].as_str().unwrap());
    wait_http(&base).await;

    // Nothing answers the shelf: ten polls a second fail. Three seconds of it is one line.
    let first =
        lines.wait_for("about shelf1 failing", |l| device_is(l, "shelf1") && l["level"] == "WARN").await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    let warnings = lines.matching(|l| device_is(l, "shelf1") && l["level"] == "WARN");
    assert_eq!(warnings.len(), 1, "{warnings:#?}");
    assert!(first["fields"]["error"].as_str().is_some_and(|e| !e.is_empty()), "{first}");

    // A job on the crane: what the crane's task logs carries the job from its span.
    let client = reqwest::Client::new();
    let to = json!({"aisle": 2, "row": 1, "bay": 3, "level": 2, "position": 1});
    let job: Value = client
        .post(format!("{base}/api/v1/jobs"))
        .json(&json!({"kind": "store", "reference": "logs-1", "barcode": "BOX-1", "to": to}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = job["id"].as_i64().unwrap_or_else(|| panic!("{job}"));
    lines
        .wait_for("in the job's span", |l| {
            device_is(l, "crane1") && span_field(l, "job", "job").is_some_and(|j| j == id)
        })
        .await;

    // The shelf's PLC goes on: one line says the device works again, with the count.
    signal(&shelf_sim, "-CONT");
    let back = lines
        .wait_for("about shelf1 working again", |l| {
            device_is(l, "shelf1")
                && l["fields"]["message"].as_str().is_some_and(|m| m.starts_with("working again"))
        })
        .await;
    assert_eq!(back["level"], "INFO", "{back}");
    assert!(back["fields"]["failures"].as_u64().is_some_and(|n| n >= 20), "{back}");

    // Access lines: method, route, path without the query, status, latency.
    // (A parameter the route takes: any other is refused.)
    let answer = client.get(format!("{base}/api/v1/jobs?reference=not-in-the-log")).send().await.unwrap();
    assert_eq!(answer.status(), 200);
    let access = lines
        .wait_for("for the GET", |l| {
            l["target"] == "rackd::access"
                && l["fields"]["path"] == "/api/v1/jobs"
                && l["fields"]["method"] == "GET"
        })
        .await;
    let fields = &access["fields"];
    assert_eq!(fields["method"], "GET", "{access}");
    assert_eq!(fields["route"], "/api/v1/jobs", "{access}");
    assert_eq!(fields["status"], 200, "{access}");
    assert!(fields["latency_ms"].as_f64().is_some_and(|ms| ms >= 0.0), "{access}");
    let all = lines.0.lock().unwrap();
    assert!(!all.iter().any(|l| l.to_string().contains("not-in-the-log")), "a query reached the log");
}
