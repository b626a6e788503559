//! `axum::serve` had no timer and no cap: half-sent requests (slowloris) held a file
//! descriptor each for ever, without a key, until rackd could accept nothing. Now a
//! connection has `server.header_timeout_ms` to send its headers and `idle_timeout_ms`
//! between requests, and at `server.max_connections` a newcomer takes the place of the
//! connection that has waited longest unserved (`rackd::app::serve`).
//!
//! The acceptance test runs `rackd serve` as a child process, at the open-files limit a
//! systemd service gets by default (1024), and counts its descriptors in `/proc/PID/fd`:
//! in-process, the flood's own sockets would be counted with the server's.

use std::process::{Command, Stdio};
use std::time::Duration;

use rackd::store::Engine;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::time::Instant;

use crate::support::ws::Ws;
use crate::support::{eventually, spawn_with, store};

/// A request line and part of the headers, then silence.
const HALF: &[u8] = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ";
const FULL: &[u8] = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";

/// Reads one response from `s` (headers and a `content-length` body): its status.
async fn response(s: &mut TcpStream) -> u16 {
    let mut got = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        if let Some(end) = got.windows(4).position(|w| w == b"\r\n\r\n") {
            let head = String::from_utf8_lossy(&got[..end]).to_lowercase();
            let length: usize = head
                .lines()
                .find_map(|l| l.strip_prefix("content-length:"))
                .map_or(0, |n| n.trim().parse().unwrap());
            if got.len() >= end + 4 + length {
                return head.split(' ').nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
            }
        }
        let n = s.read(&mut chunk).await.unwrap();
        assert!(n > 0, "closed before a whole response: {:?}", String::from_utf8_lossy(&got));
        got.extend_from_slice(&chunk[..n]);
    }
}

/// Waits for the server to close `s` (end of stream or reset): the time from `since`.
async fn closed(s: &mut TcpStream, since: Instant, within: Duration) -> Duration {
    let mut chunk = [0u8; 1024];
    match tokio::time::timeout_at(since + within, s.read(&mut chunk)).await {
        Err(_) => panic!("the server kept the connection open for {within:?}"),
        Ok(Ok(0)) | Ok(Err(_)) => since.elapsed(),
        Ok(Ok(n)) => panic!("unexpected bytes: {:?}", String::from_utf8_lossy(&chunk[..n])),
    }
}

/// `GET /healthz` on a new connection: its status.
async fn healthz(addr: &str) -> u16 {
    let mut s = TcpStream::connect(addr).await.unwrap();
    s.write_all(FULL).await.unwrap();
    response(&mut s).await
}

/// Raises this process's soft open-files limit to its hard limit if it is below `needed`.
fn raise_open_files(needed: u64) {
    use rustix::process::{Resource, getrlimit, setrlimit};
    let mut limit = getrlimit(Resource::Nofile);
    if limit.current.is_some_and(|soft| soft < needed) {
        limit.current = limit.maximum;
        setrlimit(Resource::Nofile, limit).unwrap();
    }
    let soft = getrlimit(Resource::Nofile).current;
    assert!(
        soft.is_none_or(|s| s >= needed),
        "this test opens {needed} sockets; the open-files limit is {soft:?}"
    );
}

/// `rackd serve` as a child, killed when dropped.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The soft "Max open files" of process `pid`.
fn open_files_limit(pid: u32) -> usize {
    let limits = std::fs::read_to_string(format!("/proc/{pid}/limits")).unwrap();
    let line = limits.lines().find(|l| l.starts_with("Max open files")).unwrap();
    line.split_whitespace().nth(3).unwrap().parse().unwrap()
}

/// The acceptance test: 2,000 half-open connections leave `/healthz` answering
/// within 1 s and rackd's open files under its limit. Before the fix, rackd ran out of
/// descriptors at about a thousand, and `/healthz` waited in the listen queue for ever.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_thousand_half_open_connections_leave_healthz_answering_within_a_second() {
    const FLOOD: usize = 2000;
    raise_open_files(FLOOD as u64 + 500);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("rackd.toml");
    let db = dir.path().join("rackd.db");
    std::fs::write(&file, format!("[server]\nlisten = \"127.0.0.1:0\"\n[database]\npath = {db:?}\n"))
        .unwrap();
    let log_path = dir.path().join("rackd.log");
    let log = std::fs::File::create(&log_path).unwrap();
    // `ulimit -n` sets the soft and the hard limit: rackd cannot raise it.
    let child = Command::new("sh")
        .args(["-c", "ulimit -n 1024 && exec \"$0\" serve --config \"$1\""])
        .arg(env!("CARGO_BIN_EXE_rackd"))
        .arg(&file)
        .env("RACKD_LOG", "info")
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap();
    let mut child = Child(child);
    let addr = crate::support::listening::rackd(&log_path, &mut child.0).await.to_string();
    let pid = child.0.id();
    eventually("rackd to answer /healthz", Duration::from_secs(20), async || {
        let mut s = TcpStream::connect(&addr).await.ok()?;
        s.write_all(FULL).await.ok()?;
        (response(&mut s).await == 200).then_some(())
    })
    .await;
    let limit = open_files_limit(pid);
    assert_eq!(limit, 1024);

    let mut flood = Vec::with_capacity(FLOOD);
    for _ in 0..FLOOD {
        // A connect that finds the listen queue full is sent again a second later; one that
        // waits longer finds a server that has stopped accepting (out of descriptors), and
        // the check below says what that means.
        let Ok(Ok(mut s)) = tokio::time::timeout(Duration::from_secs(3), TcpStream::connect(&addr)).await
        else {
            break;
        };
        s.write_all(HALF).await.unwrap();
        flood.push(s);
    }
    let opened = flood.len();
    let log = || std::fs::read_to_string(dir.path().join("rackd.log")).unwrap_or_default();
    let started = Instant::now();
    let status = tokio::time::timeout(Duration::from_secs(1), healthz(&addr)).await.unwrap_or_else(|_| {
        panic!(
            "/healthz did not answer within 1 s of {opened} half-open connections; rackd's log:\n{}",
            log()
        )
    });
    assert_eq!(status, 200);
    let files = std::fs::read_dir(format!("/proc/{pid}/fd")).unwrap().count();
    assert!(files < limit, "rackd has {files} files open, its limit is {limit}");
    assert_eq!(opened, FLOOD, "every connection of the flood was taken");
    assert!(started.elapsed() < Duration::from_secs(1));
    // The flood's oldest connections were closed to make room; the newest wait their turn.
    let mut oldest = flood.swap_remove(0);
    closed(&mut oldest, Instant::now(), Duration::from_secs(1)).await;
}

/// Headers within `header_timeout_ms` (from the accept, and from the first byte of each
/// keep-alive request, however slowly the bytes trickle), then `idle_timeout_ms` between
/// requests. Before the fix, none of these connections was ever closed.
#[tokio::test]
async fn a_connection_has_the_header_timeout_to_send_headers_and_the_idle_timeout_between_requests() {
    let (header, idle) = (Duration::from_millis(300), Duration::from_millis(1500));
    let app = spawn_with(Engine::Sqlite, |c| {
        c.server.header_timeout_ms = header.as_millis() as u64;
        c.server.idle_timeout_ms = idle.as_millis() as u64;
    })
    .await;
    let addr = app.base.trim_start_matches("http://").to_owned();
    let within = Duration::from_secs(10);
    // Each time is taken before the clock it checks can start on rackd's side (the accept,
    // the answer to a request): a loaded machine may run this task late, never early.
    let silent = async {
        let since = Instant::now();
        let mut s = TcpStream::connect(&addr).await.unwrap();
        closed(&mut s, since, within).await
    };
    let half = async {
        let since = Instant::now();
        let mut s = TcpStream::connect(&addr).await.unwrap();
        s.write_all(HALF).await.unwrap();
        closed(&mut s, since, within).await
    };
    // Slowloris proper: a byte of header every 50 ms, never the end of them.
    let trickle = async {
        let since = Instant::now();
        let s = TcpStream::connect(&addr).await.unwrap();
        let (mut read, mut write) = s.into_split();
        let writing = tokio::spawn(async move {
            write.write_all(HALF).await?;
            loop {
                tokio::time::sleep(Duration::from_millis(50)).await;
                write.write_all(b"x").await?;
            }
            #[allow(unreachable_code)]
            Ok::<(), std::io::Error>(())
        });
        let mut chunk = [0u8; 64];
        let took = tokio::time::timeout_at(since + within, read.read(&mut chunk)).await;
        writing.abort();
        assert!(matches!(took, Ok(Ok(0)) | Ok(Err(_))), "{took:?}");
        since.elapsed()
    };
    let kept_alive = async {
        let mut s = TcpStream::connect(&addr).await.unwrap();
        let since = Instant::now();
        s.write_all(FULL).await.unwrap();
        assert_eq!(response(&mut s).await, 200);
        closed(&mut s, since, within).await
    };
    let half_again = async {
        let mut s = TcpStream::connect(&addr).await.unwrap();
        s.write_all(FULL).await.unwrap();
        assert_eq!(response(&mut s).await, 200);
        let since = Instant::now();
        s.write_all(HALF).await.unwrap();
        closed(&mut s, since, within).await
    };
    let (silent, half, trickle, kept_alive, half_again) =
        tokio::join!(silent, half, trickle, kept_alive, half_again);
    let early = header - Duration::from_millis(10);
    for (what, took) in
        [("silent", silent), ("half", half), ("trickle", trickle), ("second request", half_again)]
    {
        assert!(
            took >= early && took < idle,
            "{what}: closed after {took:?}, the header timeout is {header:?}"
        );
    }
    assert!(
        kept_alive >= idle - Duration::from_millis(10),
        "idle: closed after {kept_alive:?}, not {idle:?}"
    );
}

/// At the cap, a new connection is served at once, in the place of the connection waiting
/// longest for its headers; a WebSocket is serving someone and keeps its place. Before the
/// fix, there was no cap, and the half-open connections stayed open.
#[tokio::test]
async fn at_the_cap_a_newcomer_takes_the_place_of_the_oldest_half_open_connection() {
    let app = spawn_with(Engine::Sqlite, |c| c.server.max_connections = 4).await;
    let addr = app.base.trim_start_matches("http://").to_owned();
    let mut ws = Ws::connect(&app.base, "?topics=jobs").await;
    assert_eq!(ws.json().await["type"], "snapshot");
    let mut half = Vec::new();
    for _ in 0..3 {
        let mut s = TcpStream::connect(&addr).await.unwrap();
        s.write_all(HALF).await.unwrap();
        half.push(s);
    }
    // Kept open: idle after its answer, since after the others began to wait.
    let mut newcomer = TcpStream::connect(&addr).await.unwrap();
    newcomer.write_all(FULL).await.unwrap();
    let status = tokio::time::timeout(Duration::from_secs(1), response(&mut newcomer)).await;
    assert_eq!(status.expect("/healthz answers within 1 s at the cap"), 200);
    closed(&mut half[0], Instant::now(), Duration::from_secs(5)).await;
    // Another newcomer (the client's own connection) takes the next one's place.
    let (status, _) = app.post("/api/v1/jobs", &store("cap-1")).await;
    assert_eq!(status, 201);
    closed(&mut half[1], Instant::now(), Duration::from_secs(5)).await;
    let events = ws.events(1).await;
    assert_eq!(events[0]["data"]["reference"], "cap-1", "{events:?}");
}

/// A stop lets the request being served finish (its body is still arriving when the stop
/// begins) and waits no longer than a second for a client that is half-way through its
/// headers. Before the fix, a half-sent request held the stop for ever.
#[tokio::test]
async fn a_stop_finishes_the_request_being_served_and_waits_for_no_half_sent_one() {
    let app = spawn_with(Engine::Sqlite, |_| {}).await;
    let addr = app.base.trim_start_matches("http://").to_owned();
    let mut half = TcpStream::connect(&addr).await.unwrap();
    half.write_all(HALF).await.unwrap();
    // A job whose body comes after the stop: the server asks for it (100 Continue) once
    // the request is being served.
    let body = serde_json::to_vec(&store("stop-1")).unwrap();
    let mut serving = TcpStream::connect(&addr).await.unwrap();
    let head = format!(
        "POST /api/v1/jobs HTTP/1.1\r\nHost: {addr}\r\ncontent-type: application/json\r\n\
         content-length: {}\r\nexpect: 100-continue\r\n\r\n",
        body.len()
    );
    serving.write_all(head.as_bytes()).await.unwrap();
    let mut continued = [0u8; 25];
    serving.read_exact(&mut continued).await.unwrap();
    assert!(continued.starts_with(b"HTTP/1.1 100 Continue"), "{:?}", String::from_utf8_lossy(&continued));

    let stopped = tokio::spawn(app.stop());
    eventually("the server to stop accepting", Duration::from_secs(5), async || {
        TcpStream::connect(&addr).await.is_err()
    })
    .await;
    let since = Instant::now();
    serving.write_all(&body).await.unwrap();
    assert_eq!(response(&mut serving).await, 201, "the request being served is answered");
    closed(&mut serving, since, Duration::from_secs(5)).await;
    let took = closed(&mut half, since, Duration::from_secs(5)).await;
    assert!(took < Duration::from_secs(3), "the half-sent request held the stop {took:?}");
    tokio::time::timeout(Duration::from_secs(5), stopped).await.expect("the server stops").unwrap();
}
