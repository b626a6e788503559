//! A seeded simulation of the wire, as FoundationDB and TigerBeetle test their I/O (the
//! tests' tool, in the library so the integration tests drive the device adapters over it
//! too, and so a field fault can be replayed in one process): the real
//! protocol clients and servers run over simulated carriers on paused tokio time, and every
//! frame they exchange goes through one scheduler that delays it by a long-tailed
//! distribution, loses it, or delivers it twice, all drawn from one seeded generator. A run
//! is a function of its seed: a failure prints the seed, and `RACKD_WIRE_SEED=N` replays it
//! (`checks.rs`).
//!
//! The carriers ([`Wire::datagrams`], [`Wire::connections`], [`Wire::line`]) are handed to
//! the clients as [`Dial`]s and to the servers as a serving datagram port or as streams,
//! exactly as the operating system's would be:
//! - **Datagrams** (UDP): each dial binds a new port, the lowest number free, so a port let
//!   go is soon another's (a rackd after a restart, a reused ephemeral port): frames still
//!   under way to it reach whoever holds the number when they land, which is how a stale
//!   reply from before a restart arrives. Datagrams are delayed independently, so they
//!   also overtake each other.
//! - **Connections** (TCP to a device that ends TCP itself): each dial opens a new
//!   connection, served by a new server task; bytes keep their order; a closed end
//!   receives nothing more.
//! - **A line** (a serial line, or a serial gateway): every dial reaches the same line
//!   again, and what is under way on it arrives whoever dialled.
//!
//! The fault model ([`Weather`]) is the one the transport's rule is proved under (its
//! module documentation): a frame arrives within the longest delay or never; a copy
//! travels right behind its original. The checks keep the clients' timeouts at or above a
//! round trip's longest delay.
//!
//! Copies: a copied reply lands right behind the original on every carrier (a device that
//! answers twice, a switch that floods). A copied *request* is another matter: the device
//! answers it again one turnaround later, which is a reply no protocol without ids can
//! tell from the next request's answer (the transport's module documentation says so: a
//! network that copies datagrams needs ids). Streams never copy a request (TCP delivers
//! once, a serial line carries what was sent once); datagrams may, and the checks let them
//! ([`Weather::copies_requests`]) on the links whose replies carry ids.

mod carriers;
#[cfg(test)]
mod checks;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard};
use std::task::Waker;
use std::time::Duration;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use tokio::sync::Notify;
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use carriers::{Accept, SimServerPort, SimStream};

use crate::protocols::transport::Dial;

/// The address of the simulated device.
pub const DEVICE: SocketAddr =
    SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::new(10, 0, 0, 2)), 502);

/// The first port a client binds.
const FIRST_PORT: u16 = 40_000;

/// What happens to frames on the wire.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weather {
    /// Share of frames lost.
    pub drop: f64,
    /// Share of frames delivered twice, the copy right behind the original.
    pub duplicate: f64,
    /// Whether requests are copied too, not only replies (see the module documentation).
    pub copies_requests: bool,
    /// The shortest one-way delay.
    pub base: Duration,
    /// The scale of the long tail added to it (a Pareto distribution, index 1.2).
    pub tail: Duration,
    /// The longest one-way delay: the tail is cut there.
    pub longest: Duration,
}

impl Weather {
    /// A wire that loses, copies and delays nothing beyond `base`.
    pub fn calm() -> Weather {
        Weather {
            drop: 0.0,
            duplicate: 0.0,
            copies_requests: false,
            base: Duration::from_micros(100),
            tail: Duration::ZERO,
            longest: Duration::from_micros(100),
        }
    }

    /// One frame's delay: `base` plus a Pareto-distributed tail cut at `longest`.
    fn delay(&self, rng: &mut StdRng) -> Duration {
        if self.tail.is_zero() {
            return self.base;
        }
        let u: f64 = rng.random_range(f64::EPSILON..1.0);
        let extra = self.tail.as_secs_f64() / u.powf(1.0 / 1.2);
        (self.base + Duration::from_secs_f64(extra.min(3600.0))).min(self.longest)
    }
}

/// Who a frame is for.
#[derive(Clone, Copy, Debug)]
enum To {
    /// A client's datagram port, by number.
    Port(u16),
    /// The serving datagram port, from a client's port.
    Server(u16),
    /// One end of a stream: connection number, and which end (0 the client's).
    End(usize, usize),
    /// The end of a stream: the other end closed.
    Eof(usize, usize),
}

/// A queue of arrived items and the task waiting for the next.
#[derive(Debug)]
struct Inbox<T> {
    items: VecDeque<T>,
    waker: Option<Waker>,
}

impl<T> Default for Inbox<T> {
    fn default() -> Self {
        Inbox { items: VecDeque::new(), waker: None }
    }
}

impl<T> Inbox<T> {
    fn push(&mut self, item: T) {
        self.items.push_back(item);
        if let Some(w) = self.waker.take() {
            w.wake();
        }
    }
}

/// One end of a stream.
#[derive(Debug, Default)]
struct End {
    inbox: Inbox<u8>,
    /// The other end closed and everything it sent has arrived.
    eof: bool,
    /// This end closed: it receives nothing more.
    closed: bool,
    /// When the last frame sent from this end lands (bytes keep their order).
    last_at: Option<Instant>,
}

/// The network's state.
struct Net {
    rng: StdRng,
    weather: Weather,
    seq: u64,
    queue: BTreeMap<(Instant, u64), (To, Vec<u8>)>,
    ports: BTreeMap<u16, Inbox<Vec<u8>>>,
    server: Inbox<(u16, Vec<u8>)>,
    streams: Vec<[End; 2]>,
    /// `RACKD_WIRE_TRACE` is set: every frame landing is printed.
    trace: bool,
}

/// A simulated network between clients and one device.
#[derive(Clone)]
pub struct Wire {
    net: Arc<Mutex<Net>>,
    notify: Arc<Notify>,
    _deliverer: Arc<AbortOnDrop>,
}

/// Aborts a task when dropped.
pub struct AbortOnDrop(pub JoinHandle<()>);

impl Drop for AbortOnDrop {
    fn drop(&mut self) {
        self.0.abort();
    }
}

impl Wire {
    /// A wire whose every random choice comes from `seed`; calm until
    /// [`Wire::set_weather`]. Needs a tokio runtime (it spawns its delivery task).
    pub fn new(seed: u64) -> Wire {
        let net = Net {
            rng: StdRng::seed_from_u64(seed),
            weather: Weather::calm(),
            seq: 0,
            queue: BTreeMap::new(),
            ports: BTreeMap::new(),
            server: Inbox::default(),
            streams: Vec::new(),
            trace: std::env::var_os("RACKD_WIRE_TRACE").is_some(),
        };
        let net = Arc::new(Mutex::new(net));
        let notify = Arc::new(Notify::new());
        let task = tokio::spawn(deliver(net.clone(), notify.clone()));
        Wire { net, notify, _deliverer: Arc::new(AbortOnDrop(task)) }
    }

    fn net(&self) -> MutexGuard<'_, Net> {
        self.net.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Changes what happens to frames sent from now on.
    pub fn set_weather(&self, weather: Weather) {
        self.net().weather = weather;
    }

    /// A number drawn from the wire's generator, for the checks' own choices (so one seed
    /// decides everything).
    pub fn roll(&self, below: u64) -> u64 {
        self.net().rng.random_range(0..below.max(1))
    }

    /// Datagram ports for a client: each dial binds the lowest free port number.
    pub fn datagrams(&self) -> Arc<dyn Dial> {
        Arc::new(carriers::DatagramDial(self.clone()))
    }

    /// The device's serving datagram port.
    pub fn server_port(&self) -> SimServerPort {
        SimServerPort(self.clone())
    }

    /// Connections for a client: each dial opens one, handed to `accept` for the device.
    pub fn connections(&self, accept: Accept) -> Arc<dyn Dial> {
        Arc::new(carriers::ConnectionDial { wire: self.clone(), accept })
    }

    /// A line: its device end (for the server), and the dial that reaches its client end.
    pub fn line(&self) -> (carriers::SimStream, Arc<dyn Dial>) {
        let conn = self.open_stream();
        let device = carriers::SimStream::new(self.clone(), conn, 1, false);
        (device, Arc::new(carriers::LineDial { wire: self.clone(), conn }))
    }

    fn open_stream(&self) -> usize {
        let mut net = self.net();
        net.streams.push([End::default(), End::default()]);
        net.streams.len() - 1
    }

    /// Sends `bytes` to `to` through the weather.
    fn send(&self, to: To, bytes: &[u8]) {
        let mut net = self.net();
        let weather = net.weather;
        if weather.drop > 0.0 && net.rng.random_bool(weather.drop) {
            return;
        }
        let request = matches!(to, To::Server(_) | To::End(_, 1));
        let copy = weather.duplicate > 0.0
            && net.rng.random_bool(weather.duplicate)
            && (weather.copies_requests || !request);
        let mut at = Instant::now() + weather.delay(&mut net.rng);
        // A stream keeps its bytes in order: nothing lands before what went first.
        if let To::End(conn, end) = to {
            let from = &mut net.streams[conn][1 - end];
            at = at.max(from.last_at.unwrap_or(at));
            from.last_at = Some(at);
        }
        let copy = copy.then(|| (to, bytes.to_vec()));
        net.schedule(at, to, bytes.to_vec());
        if let Some((to, bytes)) = copy {
            net.schedule(at, to, bytes);
        }
        drop(net);
        self.notify.notify_one();
    }

    /// Marks end `end` of connection `conn` closed; the other end reads the end of the
    /// stream once what was sent before has landed.
    fn close(&self, conn: usize, end: usize) {
        let mut net = self.net();
        net.streams[conn][end].closed = true;
        let at = net.streams[conn][end].last_at.unwrap_or_else(Instant::now).max(Instant::now());
        net.schedule(at, To::Eof(conn, 1 - end), Vec::new());
        drop(net);
        self.notify.notify_one();
    }
}

impl Net {
    fn schedule(&mut self, at: Instant, to: To, bytes: Vec<u8>) {
        self.seq += 1;
        self.queue.insert((at, self.seq), (to, bytes));
    }

    /// Binds the lowest free port number.
    fn bind(&mut self) -> u16 {
        let bound: BTreeSet<u16> = self.ports.keys().copied().collect();
        let port = (FIRST_PORT..).find(|p| !bound.contains(p)).unwrap_or(FIRST_PORT);
        self.ports.insert(port, Inbox::default());
        port
    }

    /// Hands one frame to whoever holds its destination now; a frame for no one is lost.
    fn land(&mut self, to: To, bytes: Vec<u8>) {
        if self.trace {
            let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
            eprintln!("wire {:?} lands {to:?} {hex}", Instant::now());
        }
        match to {
            To::Port(port) => {
                if let Some(inbox) = self.ports.get_mut(&port) {
                    inbox.push(bytes);
                }
            }
            To::Server(from) => self.server.push((from, bytes)),
            To::End(conn, end) => {
                let end = &mut self.streams[conn][end];
                if !end.closed {
                    end.inbox.items.extend(bytes);
                    if let Some(w) = end.inbox.waker.take() {
                        w.wake();
                    }
                }
            }
            To::Eof(conn, end) => {
                let end = &mut self.streams[conn][end];
                end.eof = true;
                if let Some(w) = end.inbox.waker.take() {
                    w.wake();
                }
            }
        }
    }
}

/// The delivery task: lands each frame when its time comes, in time order (frames due at
/// the same instant in the order they were sent).
async fn deliver(net: Arc<Mutex<Net>>, notify: Arc<Notify>) {
    loop {
        let next = {
            let mut net = net.lock().unwrap_or_else(|p| p.into_inner());
            let now = Instant::now();
            while let Some(entry) = net.queue.first_entry() {
                if entry.key().0 > now {
                    break;
                }
                let (to, bytes) = entry.remove();
                net.land(to, bytes);
            }
            net.queue.first_key_value().map(|(k, _)| k.0)
        };
        match next {
            Some(at) => {
                tokio::select! {
                    () = tokio::time::sleep_until(at) => {}
                    () = notify.notified() => {}
                }
            }
            None => notify.notified().await,
        }
    }
}
