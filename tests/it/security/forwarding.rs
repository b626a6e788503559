//! A standby's forwarding to the active node (finding: it honoured `HTTP_PROXY`, spoke
//! plain HTTP only, buffered 16 MiB whatever the API's body limit, and dropped `?token=`,
//! so such a client got 401 from the active node).
//!
//! Two nodes of one cluster on the test PostgreSQL, with an API key; the active node is
//! `a`, the standby `b` (in this process, or a `rackd serve` process where its environment
//! matters). Configuration is written as TOML, as a site writes it.

use std::net::SocketAddr;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use rackd::auth::KeyHash;
use rackd::config::{ClusterConfig, KeyConfig};
use rackd::store::Database;
use serde_json::{Value, json};

use crate::support::tls::{Ca, TlsFront};
use crate::support::{TestApp, eventually, spawn_on, split};

const KEY: &str = "rk_forwarding-test-key-0123456789";

fn key_entry() -> String {
    format!("name = \"wms\"\nrole = \"admin\"\nhash = \"{}\"\n", KeyHash::of(KEY))
}

fn keys() -> Vec<KeyConfig> {
    vec![toml::from_str(&key_entry()).unwrap()]
}

/// A `[cluster]` table's text, as a node's file has it.
fn cluster(text: &str) -> ClusterConfig {
    toml::from_str(text).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// A node of the cluster on `db`, without devices, with the key; `edit` changes the rest.
async fn node(db: &str, table: &str, edit: impl FnOnce(&mut rackd::config::Config)) -> TestApp {
    let cluster = cluster(table);
    spawn_on(Database::Postgres(db.to_owned()), move |c| {
        c.devices = Vec::new();
        c.auth.keys = keys();
        c.cluster = Some(cluster);
        edit(c);
    })
    .await
}

async fn get(base: &str, path: &str, key: Option<&str>) -> (u16, Value) {
    let client = reqwest::Client::new();
    let mut request = client.get(format!("{base}{path}"));
    if let Some(key) = key {
        request = request.bearer_auth(key);
    }
    split(request.send().await.unwrap()).await
}

/// Waits until the node at `base` sees `a` as the active node, with its URL.
async fn sees_active(base: &str) {
    eventually(format!("{base} to see the active node"), Duration::from_secs(15), async || {
        // A node still starting (a process) refuses the connection: not yet.
        let sent = reqwest::Client::new().get(format!("{base}/api/v1/cluster")).bearer_auth(KEY).send().await;
        let (status, view) = match sent {
            Ok(r) => split(r).await,
            Err(e) => return Err(e.to_string()),
        };
        let nodes = view["nodes"].as_array().cloned().unwrap_or_default();
        let ok = status == 200 && view["lease"]["holder"] == "a" && nodes.iter().any(|n| n["name"] == "a");
        if ok { Ok(()) } else { Err(format!("{status} {view}")) }
    })
    .await
}

/// Counts the connections made to it; nothing is answered.
struct Trap {
    addr: SocketAddr,
    hits: Arc<AtomicUsize>,
}

impl Trap {
    async fn new() -> Trap {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let hits = Arc::new(AtomicUsize::new(0));
        let counted = hits.clone();
        tokio::spawn(async move {
            while let Ok((tcp, _)) = listener.accept().await {
                counted.fetch_add(1, Ordering::SeqCst);
                drop(tcp);
            }
        });
        Trap { addr, hits }
    }
}

/// `rackd serve` in the background, killed when dropped.
struct Server(std::process::Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_standby_forwards_past_the_proxy_its_environment_names() {
    let db = crate::support::postgres::database().await;
    let a = node(&db, "node = \"a\"", |_| {}).await;
    sees_active(&a.base).await;

    // b as a process whose environment sends every HTTP request through a proxy: a
    // listener that counts who comes.
    let trap = Trap::new().await;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("b.toml");
    let text = format!(
        "[server]\nlisten = \"127.0.0.1:0\"\n[database]\nurl = \"{db}\"\n[cluster]\nnode = \"b\"\n\
         [[auth.keys]]\n{}",
        key_entry()
    );
    std::fs::write(&file, text).unwrap();
    let proxy = format!("http://{}", trap.addr);
    let log = dir.path().join("b.log");
    let mut command = Command::new(env!("CARGO_BIN_EXE_rackd"));
    command.args(["serve", "--config", file.to_str().unwrap()]).env("RACKD_LOG", "info");
    command.stdout(Stdio::null()).stderr(std::fs::File::create(&log).unwrap());
    for var in ["HTTP_PROXY", "http_proxy", "HTTPS_PROXY", "https_proxy", "ALL_PROXY", "all_proxy"] {
        command.env(var, &proxy);
    }
    let mut node_b = Server(command.env_remove("NO_PROXY").env_remove("no_proxy").spawn().unwrap());
    let b = format!("http://{}", crate::support::listening::rackd(&log, &mut node_b.0).await);
    sees_active(&b).await;

    let (status, devices) = get(&b, "/api/v1/devices", Some(KEY)).await;
    assert_eq!((status, devices), (200, json!([])), "forwarded to a, straight");
    assert_eq!(trap.hits.load(Ordering::SeqCst), 0, "the proxy saw the forwarded request (and its key)");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_body_over_the_standbys_limit_is_refused_by_the_standby() {
    let db = crate::support::postgres::database().await;
    let a = node(&db, "node = \"a\"", |_| {}).await;
    sees_active(&a.base).await;
    // b takes at most 64 KiB, as its own routes do; a (2 MiB) would take this body.
    let b = node(&db, "node = \"b\"", |c| c.server.body_limit_bytes = 64 * 1024).await;
    sees_active(&b.base).await;
    let body = json!({"reason": "x".repeat(256 * 1024)});
    let r = reqwest::Client::new()
        .post(b.url("/api/v1/aisles/1/pause"))
        .bearer_auth(KEY)
        .json(&body)
        .send()
        .await
        .unwrap();
    let got = split(r).await;
    crate::support::assert_error(&got, 413, "body_too_large");
    let (_, aisles) = get(&a.base, "/api/v1/aisles", Some(KEY)).await;
    let one = aisles.as_array().and_then(|l| l.iter().find(|x| x["aisle"] == 1)).cloned();
    assert_eq!(
        one.map(|a| a["paused"].clone()),
        Some(json!(false)),
        "nothing reached the active node: {aisles}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_key_in_the_query_is_answered_by_a_standby_as_by_the_active_node() {
    let db = crate::support::postgres::database().await;
    let a = node(&db, "node = \"a\"", |_| {}).await;
    sees_active(&a.base).await;
    let b = node(&db, "node = \"b\"", |_| {}).await;
    sees_active(&b.base).await;
    // A standby answers as the active node does (400 `token_in_query`: the key is refused
    // in a URL before anything is forwarded); it must neither drop the key on the way
    // (401 before the fix) nor carry it on in the URL.
    let path = format!("/api/v1/devices?token={KEY}");
    let (direct, _) = get(&a.base, &path, None).await;
    let (forwarded, body) = get(&b.base, &path, None).await;
    assert_eq!(forwarded, direct, "{body}");
    assert_eq!(direct, 400, "{body}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_standby_forwards_over_https_trusting_the_cluster_ca_and_nothing_else() {
    let db = crate::support::postgres::database().await;
    let ca = Ca::new("rackd test cluster CA");
    let front = TlsFront::bind(&ca.server()).await;
    let url = format!("https://localhost:{}", front.addr.port());
    let a = node(&db, &format!("node = \"a\"\nurl = \"{url}\""), |_| {}).await;
    front.forward_to(a.base.trim_start_matches("http://").parse().unwrap());
    sees_active(&a.base).await;

    let dir = tempfile::tempdir().unwrap();
    let ca_file = ca.write(dir.path(), "cluster-ca.pem");
    let table = format!("node = \"b\"\nca_file = {}", toml::Value::String(ca_file.display().to_string()));
    let b = node(&db, &table, |_| {}).await;
    sees_active(&b.base).await;
    let (status, devices) = get(&b.base, "/api/v1/devices", Some(KEY)).await;
    assert_eq!((status, devices), (200, json!([])), "forwarded over https");

    // Without the site's CA, the system's roots do not vouch for a's certificate.
    let c = node(&db, "node = \"c\"", |_| {}).await;
    sees_active(&c.base).await;
    let got = get(&c.base, "/api/v1/devices", Some(KEY)).await;
    crate::support::assert_error(&got, 503, "unavailable");
}
