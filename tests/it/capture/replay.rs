//! A site's problem in the lab: a crane hand-over whose ACK came late, recorded between a
//! real rackd and the crane simulator by a recording proxy, written as a capture, then
//! played back by the replay ([`rackd::sim::replay`]) to a fresh rackd, which must reach
//! the same result: the job completes through the same states, the replay sees no
//! divergence, and the strobe waits for the ACK as long as it did.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use rackd::capture::{Direction, Frame, Link, Transport, read_file};
use rackd::protocols::mc3e::TransportKind;
use rackd::sim::crane::Hold;
use rackd::sim::replay::{DEFAULT_REORDER, ReplayServer, Script};
use rackd::store::Engine;
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

use crate::crane::{cloc, crane, device_at, history, submit, wait_job, with_crane};
use crate::support::{TestApp, eventually, spawn_with};

/// How long the crane withholds its ACK after rackd raised the strobe.
const LATE: Duration = Duration::from_millis(400);

/// A TCP proxy that keeps every MC 3E frame each way as a [`Frame`] (rackd to the crane:
/// sent), cut by the frame's own length field, whatever TCP made of it.
struct Recorder {
    addr: SocketAddr,
    frames: Arc<Mutex<Vec<Frame>>>,
    /// rackd's end of the last connection.
    client: Arc<Mutex<Option<SocketAddr>>>,
}

impl Recorder {
    async fn to(server: SocketAddr) -> Recorder {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let (frames, client) = (Arc::new(Mutex::new(Vec::new())), Arc::new(Mutex::new(None)));
        let (f, c) = (frames.clone(), client.clone());
        tokio::spawn(async move {
            while let Ok((down, peer)) = listener.accept().await {
                let Ok(up) = TcpStream::connect(server).await else { continue };
                *c.lock().unwrap() = Some(peer);
                let (dr, dw) = down.into_split();
                let (ur, uw) = up.into_split();
                tokio::spawn(pipe(dr, uw, f.clone(), Direction::Sent));
                tokio::spawn(pipe(ur, dw, f.clone(), Direction::Received));
            }
        });
        Recorder { addr, frames, client }
    }

    /// The frames so far, and the link they were on (rackd's end, the proxy's).
    fn capture(&self) -> (Link, Vec<Frame>) {
        let local = self.client.lock().unwrap().expect("rackd connected");
        (
            Link::Ip { transport: Transport::Tcp, local, remote: self.addr },
            self.frames.lock().unwrap().clone(),
        )
    }
}

/// The length of the MC 3E frame at the start of `buf` (request `50 00` or response
/// `D0 00`: nine bytes of header, then the length field's count), once it is all there.
fn mc3e_len(buf: &[u8]) -> Option<usize> {
    let len = 9 + usize::from(u16::from_le_bytes([*buf.get(7)?, *buf.get(8)?]));
    (buf.len() >= len).then_some(len)
}

async fn pipe(
    mut from: impl AsyncReadExt + Unpin,
    mut to: impl AsyncWriteExt + Unpin,
    frames: Arc<Mutex<Vec<Frame>>>,
    direction: Direction,
) {
    let (mut buf, mut pending) = (vec![0u8; 8192], Vec::new());
    while let Ok(n @ 1..) = from.read(&mut buf).await {
        pending.extend_from_slice(&buf[..n]);
        let now = SystemTime::now().duration_since(UNIX_EPOCH).unwrap().as_micros() as u64;
        while let Some(len) = mc3e_len(&pending) {
            let frame: Vec<u8> = pending.drain(..len).collect();
            frames.lock().unwrap().push(Frame::new(direction, now, frame));
        }
        if to.write_all(&buf[..n]).await.is_err() {
            return;
        }
    }
}

/// The time of the first write of `value` to D`register` (one word), in µs.
fn written_at(frames: &[Frame], register: u8, value: u8) -> u64 {
    // 3E batch write, D (A8), one point: command 01 14, head, then the word.
    let wanted = |b: &[u8]| {
        b.len() == 23 && b[11..13] == [1, 0x14] && b[15..19] == [register, 0, 0, 0xA8] && b[21] == value
    };
    let f = frames.iter().find(|f| f.direction == Direction::Sent && wanted(&f.bytes));
    f.unwrap_or_else(|| panic!("no write of {value} to D{register}")).time_us
}

/// How long rackd's strobe stayed up: from STB := 1 to STB := 0 (it lowers it as soon as
/// it reads ACK = 1).
fn strobe_up(frames: &[Frame]) -> Duration {
    Duration::from_micros(written_at(frames, 21, 0) - written_at(frames, 21, 1))
}

fn travel() -> Value {
    json!({"kind": "travel", "to": cloc(1, 9, 4, 1)})
}

/// rackd with the crane at `address`, its job posted at once (before the crane is online,
/// so that the conversation alone decides when the hand-over starts). rackd reads only the
/// ACK while it waits for it, so the heartbeat's loss timeout is well over the late ACK.
async fn rackd_with_job(address: SocketAddr) -> (TestApp, i64) {
    let device = device_at(&address.to_string(), TransportKind::Tcp, |d| {
        d.handshake_timeout_ms = 3000;
        d.heartbeat_timeout_ms = 2000;
    });
    let app = spawn_with(Engine::Sqlite, |c| with_crane(c, device)).await;
    let id = submit(&app, travel(), "replayed").await;
    (app, id)
}

/// Completed, and its states in order.
async fn completed(app: &TestApp, id: i64, secs: u64) -> Vec<String> {
    let job = wait_job(app, id, &["completed", "failed", "cancelled"], secs).await;
    assert_eq!(job["state"], "completed", "{job}");
    history(app, id).await.into_iter().map(|(state, _)| state).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_late_ack_recorded_at_a_site_replays_into_a_fresh_rackd_with_the_same_result() {
    // The site: a crane that takes its time to acknowledge the strobe.
    let sim = crane(TransportKind::Tcp, 20).await;
    sim.hold(Some(Hold::BeforeAck));
    let recorder = Recorder::to(sim.local_addr()).await;
    let (app, id) = rackd_with_job(recorder.addr).await;
    eventually(
        "the strobe",
        Duration::from_secs(5),
        async || if sim.word(21) == 1 { Ok(()) } else { Err(()) },
    )
    .await;
    tokio::time::sleep(LATE).await;
    sim.hold(None);
    let states = completed(&app, id, 8).await;
    // rackd acknowledges the completion once it is stored (D22 := 1, the crane clears
    // D223, D22 := 0): the recording holds the whole acknowledgement before rackd stops,
    // or the lab's rackd would make writes the site's never made.
    eventually("the acknowledgement", Duration::from_secs(5), async || {
        if sim.word(223) == 0 && sim.word(22) == 0 { Ok(()) } else { Err((sim.word(223), sim.word(22))) }
    })
    .await;
    app.stop().await;
    drop(sim);
    let (link, frames) = recorder.capture();
    let recorded_wait = strobe_up(&frames);
    assert!(recorded_wait >= LATE, "the ACK was late at the site: {recorded_wait:?}");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.pcapng");
    rackd::capture::write(std::fs::File::create(&file).unwrap(), &link, &frames).unwrap();

    // The lab: the capture's device side, and a fresh rackd on a fresh database.
    let capture = read_file(&file).unwrap();
    assert_eq!((capture.link, capture.frames.len()), (link, frames.len()));
    let script = Script::new(&read_file(&file).unwrap()).unwrap();
    let replay = ReplayServer::start(script, "127.0.0.1:0".parse().unwrap(), DEFAULT_REORDER).await.unwrap();
    let lab = Recorder::to(replay.local_addr()).await;
    let (app, replayed_id) = rackd_with_job(lab.addr).await;
    assert_eq!(replayed_id, id, "the same job id, so the same task number");
    let ended = tokio::time::timeout(Duration::from_secs(8), completed(&app, replayed_id, 60)).await;
    let Ok(replayed_states) = ended else {
        panic!("the replayed job did not end within 8 s; the replay:\n{}", replay.stop());
    };
    app.stop().await;
    let report = replay.stop();
    eprintln!("{report}");
    assert_eq!(replayed_states, states, "{report}");
    // Every request answered. On a quiet machine nothing diverges; with a dozen tests
    // running at once, rackd's own timing can put a poll ahead of a write by more than the
    // tolerance: the replay then flags it and skips ahead (the outcome above is the same).
    assert_eq!(report.counters.unanswered, 0, "{report}");
    assert!(report.counters.skipped <= 2, "{report}");
    assert!(report.counters.matched > 20, "{report}");
    let (_, lab_frames) = lab.capture();
    let replayed_wait = strobe_up(&lab_frames);
    assert!(
        replayed_wait >= LATE && replayed_wait + Duration::from_millis(30) >= recorded_wait,
        "the strobe waited {replayed_wait:?} for the ACK in the lab, {recorded_wait:?} at the site"
    );
}
