//! Every client over the simulated wire: thousands of requests per seed against the real
//! protocol server's memory, which holds a value derived from each word's address, so an
//! answer that belongs to another request shows. The check is that **every value a read
//! returned is the value at the address it asked for**; requests may fail (the weather
//! can be foul), but not too many (so the check is not vacuous).
//!
//! Each seed chooses the weather (loss, copies, the delay's tail), the reads and writes
//! (sizes from one word to a task slot's 35, so sizes collide), callers that give up
//! mid-request, and restarts (a new client on the same wire while the old one's frames are
//! still under way: a reused port or the same line brings them to the new one).
//!
//! Seeds: `cargo test --lib simwire` runs [`SEEDS`] per protocol and framing (14 of them, so
//! over a thousand in all). `RACKD_WIRE_SEED=N` runs seed `N` alone, `RACKD_WIRE_SEEDS=K`
//! and `RACKD_WIRE_FIRST=F` run seeds `F..F+K` of every case, `RACKD_WIRE_REQUESTS=R`
//! sets the requests per seed, and `RACKD_WIRE_TRACE=1` prints each read with its virtual
//! time and answer (with a single seed, to see where a failing one went wrong); a million
//! seeds locally:
//!
//! ```text
//! RACKD_WIRE_SEEDS=72000 cargo test --release --lib simwire -- --test-threads 2
//! ```

use std::any::Any;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::{AbortOnDrop, DEVICE, Weather, Wire};
use crate::protocols::mc3e::{self, FrameKind, Mc3eClient, Mc3eConfig, Mc3eServer, TransportKind};
use crate::protocols::mewtocol::{self, MewtocolClient, MewtocolConfig, MewtocolTransport};
use crate::protocols::modbus::server::{Bank, ModbusServer, ServerOptions};
use crate::protocols::modbus::{ModbusClient, ModbusConfig, Quirks, Transport};
use crate::protocols::ppi::{self, PpiClient, PpiConfig, PpiTransport};
use crate::protocols::transport::{Dial, LinkTuning};
use crate::protocols::{PlcError, PlcMemory};

/// Seeds per case in `cargo test`.
const SEEDS: u64 = 80;

/// Requests per seed in `cargo test`.
const REQUESTS: u64 = 1000;

/// Words of memory the requests address.
const WORDS: u32 = 240;

/// Sizes of reads and writes: a word, two, a block, a task slot.
const SIZES: [u16; 4] = [1, 2, 8, 35];

/// The reply lifetime every client is configured with: above the longest round trip.
const TIMEOUT: Duration = Duration::from_millis(100);

/// A protocol and framing under test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Case {
    ModbusUdp,
    ModbusUdpNoTid,
    ModbusTcp,
    ModbusTcpNoTid,
    ModbusRtu,
    ModbusRtuGateway,
    Mc3eTcp,
    Mc3eUdp,
    Mc4eTcp,
    Mc4eUdp,
    Mewtocol,
    MewtocolGateway,
    Ppi,
    PpiGateway,
}

/// What keeps a simulated device running.
type Running = Box<dyn Any + Send>;

impl Case {
    /// The device on `wire`, and the dial that reaches it.
    fn device(self, wire: &Wire) -> (Running, Arc<dyn Dial>) {
        match self {
            Case::ModbusUdp | Case::ModbusUdpNoTid => {
                let options = ServerOptions {
                    zero_transaction_id: self == Case::ModbusUdpNoTid,
                    length0: true,
                    ..ServerOptions::default()
                };
                let server = ModbusServer::new(Arc::new(Bank::new()), options);
                (Box::new(server.serve_datagrams(wire.server_port())), wire.datagrams())
            }
            Case::ModbusTcp | Case::ModbusTcpNoTid => {
                let options = ServerOptions {
                    zero_transaction_id: self == Case::ModbusTcpNoTid,
                    ..ServerOptions::default()
                };
                let server = ModbusServer::new(Arc::new(Bank::new()), options);
                let handles = Arc::new(Mutex::new(Vec::new()));
                let kept = handles.clone();
                let accept = Arc::new(move |stream| {
                    kept.lock().unwrap().push(server.serve_mbap_stream(stream));
                });
                (Box::new(handles), wire.connections(accept))
            }
            Case::ModbusRtu | Case::ModbusRtuGateway => {
                let (device, dial) = wire.line();
                let server = ModbusServer::new(Arc::new(Bank::new()), ServerOptions::default());
                (Box::new(server.serve_rtu_stream(device, 115_200)), dial)
            }
            Case::Mc3eTcp | Case::Mc4eTcp => {
                let state = mc3e::ServerState::new(mc3e::Bank::default().shared());
                let tasks = Arc::new(Mutex::new(Vec::new()));
                let kept = tasks.clone();
                let accept = Arc::new(move |stream| {
                    let task = Mc3eServer::serve_stream(stream, DEVICE, state.clone());
                    kept.lock().unwrap().push(AbortOnDrop(task));
                });
                (Box::new(tasks), wire.connections(accept))
            }
            Case::Mc3eUdp | Case::Mc4eUdp => {
                let state = mc3e::ServerState::new(mc3e::Bank::default().shared());
                (Box::new(Mc3eServer::serve_datagrams(wire.server_port(), DEVICE, state)), wire.datagrams())
            }
            Case::Mewtocol | Case::MewtocolGateway => {
                let (device, dial) = wire.line();
                let state = mewtocol::ServerState::new(mewtocol::Bank::default().shared());
                (Box::new(mewtocol::server::serve_stream(device, state)), dial)
            }
            Case::Ppi | Case::PpiGateway => {
                let (device, dial) = wire.line();
                let state = ppi::ServerState::new(ppi::Bank::default().shared());
                (Box::new(ppi::server::serve_stream(device, state)), dial)
            }
        }
    }

    /// A new client of the device, as a device adapter has it.
    fn client(self, dial: Arc<dyn Dial>) -> Arc<dyn PlcMemory> {
        let modbus = |transport, quirks: Quirks| {
            let mut config = ModbusConfig::new(transport, "simulated");
            config.timeout = TIMEOUT;
            config.quirks = quirks;
            config.serial.baud = 115_200;
            config.tuning = LinkTuning::for_replies(config.replies());
            Arc::new(ModbusClient::over(config, dial.clone()).unwrap()) as Arc<dyn PlcMemory>
        };
        let mc = |transport, frame| {
            let mut config = Mc3eConfig::new("simulated", transport);
            config.link.timeout = TIMEOUT;
            config.monitor_timer = 0;
            config.frame = frame;
            config.link.tuning = LinkTuning::for_replies(config.replies());
            Arc::new(Mc3eClient::over(config, dial.clone())) as Arc<dyn PlcMemory>
        };
        let no_tid = Quirks { length0: true, ignore_transaction_id: true };
        match self {
            Case::ModbusUdp => modbus(Transport::Udp, Quirks { length0: true, ignore_transaction_id: false }),
            Case::ModbusUdpNoTid => modbus(Transport::Udp, no_tid),
            Case::ModbusTcp => modbus(Transport::Tcp, Quirks::default()),
            Case::ModbusTcpNoTid => modbus(Transport::Tcp, Quirks { length0: false, ..no_tid }),
            Case::ModbusRtu => modbus(Transport::RtuSerial, Quirks::default()),
            Case::ModbusRtuGateway => modbus(Transport::RtuOverTcp, Quirks::default()),
            Case::Mc3eTcp => mc(TransportKind::Tcp, FrameKind::E3),
            Case::Mc3eUdp => mc(TransportKind::Udp, FrameKind::E3),
            Case::Mc4eTcp => mc(TransportKind::Tcp, FrameKind::E4),
            Case::Mc4eUdp => mc(TransportKind::Udp, FrameKind::E4),
            Case::Mewtocol | Case::MewtocolGateway => {
                let transport = match self {
                    Case::Mewtocol => MewtocolTransport::Serial,
                    _ => MewtocolTransport::Tcp,
                };
                let mut config = MewtocolConfig::new(transport, "simulated");
                config.timeout = TIMEOUT;
                config.tuning = LinkTuning::for_replies(crate::protocols::Replies::Unnamed);
                Arc::new(MewtocolClient::over(config, dial).unwrap())
            }
            Case::Ppi | Case::PpiGateway => {
                let transport = match self {
                    Case::Ppi => PpiTransport::Serial,
                    _ => PpiTransport::Tcp,
                };
                let mut config = PpiConfig::new(transport, "simulated");
                // The two-step exchange takes two round trips.
                config.timeout = TIMEOUT * 2;
                config.tuning = LinkTuning::for_replies(crate::protocols::Replies::Unnamed);
                Arc::new(PpiClient::over(config, dial).unwrap())
            }
        }
    }

    /// The first word of the memory the requests address, in the protocol's notation.
    fn base(self) -> &'static str {
        match self {
            Case::ModbusUdp
            | Case::ModbusUdpNoTid
            | Case::ModbusTcp
            | Case::ModbusTcpNoTid
            | Case::ModbusRtu
            | Case::ModbusRtuGateway => "4x100",
            Case::Mc3eTcp | Case::Mc3eUdp | Case::Mc4eTcp | Case::Mc4eUdp => "D100",
            Case::Mewtocol | Case::MewtocolGateway => "DT100",
            Case::Ppi | Case::PpiGateway => "VW200",
        }
    }
}

/// The value the memory holds at word `i`: different for every word of the range, so a
/// shifted or another request's answer shows.
pub(crate) fn value(i: u32) -> u16 {
    (i.wrapping_mul(40_503) ^ (i << 7) ^ 0x5A5A) as u16
}

/// What one seed did.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Outcome {
    pub reads: u64,
    pub answered: u64,
    pub failed: u64,
    pub abandoned: u64,
    pub restarts: u64,
    pub timeouts: u64,
    pub stale: u64,
}

/// The weather of a seed: loss, copies and the delay's tail, drawn from the wire. Requests
/// are copied on datagram links whose replies carry ids (see the module documentation of
/// [`super`]).
fn weather(case: Case, wire: &Wire) -> Weather {
    let drop = [0.0, 0.02, 0.1, 0.2][wire.roll(4) as usize];
    let duplicate = [0.0, 0.01, 0.05][wire.roll(3) as usize];
    let tail = Duration::from_micros([100, 500, 2000][wire.roll(3) as usize]);
    Weather {
        drop,
        duplicate,
        copies_requests: matches!(case, Case::ModbusUdp | Case::Mc4eUdp),
        base: Duration::from_micros(100),
        tail,
        longest: TIMEOUT / 2 - Duration::from_millis(3),
    }
}

/// Runs `requests` requests of `case` over a wire seeded with `seed`; panics, naming the
/// seed, at the first answer that is not the memory at the address asked.
pub(crate) async fn run(case: Case, seed: u64, requests: u64) -> Outcome {
    let wire = Wire::new(seed);
    let (_device, dial) = case.device(&wire);
    let mut plc = case.client(dial.clone());
    let base = plc.parse_address(case.base()).unwrap();
    let at = |plc: &Arc<dyn PlcMemory>, i: u32| plc.word_address(&base, i);
    let values: Vec<u16> = (0..WORDS).map(value).collect();
    for (n, chunk) in values.chunks(30).enumerate() {
        let start = at(&plc, n as u32 * 30);
        plc.write_words(&start, chunk).await.unwrap_or_else(|e| panic!("{case:?} seed {seed}: filling: {e}"));
    }
    wire.set_weather(weather(case, &wire));
    let mut out = Outcome::default();
    let mut stats_before = (0, 0);
    let trace = std::env::var_os("RACKD_WIRE_TRACE").is_some();
    let t0 = tokio::time::Instant::now();
    for n in 0..requests {
        let roll = wire.roll(1000);
        if roll < 3 {
            // A restart: a new client while the old one's frames are under way.
            let stats = plc.link_stats();
            stats_before = (stats_before.0 + stats.timeouts, stats_before.1 + stats.stale);
            plc = case.client(dial.clone());
            out.restarts += 1;
            continue;
        }
        let count = SIZES[wire.roll(SIZES.len() as u64) as usize];
        let first = wire.roll(u64::from(WORDS - u32::from(count) + 1)) as u32;
        let start = at(&plc, first);
        let expected = &values[first as usize..first as usize + count as usize];
        if roll < 100 {
            if let Err(e) = plc.write_words(&start, expected).await {
                assert!(retryable(&e), "{case:?} seed {seed}, request {n}: write {first}+{count}: {e}");
            }
            continue;
        }
        out.reads += 1;
        let read = plc.read_words(&start, count);
        let got = if roll < 130 {
            // A caller that gives up mid-request (a WMS's own timeout).
            let patience = Duration::from_micros(wire.roll(120_000));
            match tokio::time::timeout(patience, read).await {
                Ok(got) => got,
                Err(_) => {
                    out.abandoned += 1;
                    continue;
                }
            }
        } else {
            read.await
        };
        if trace {
            let ms = t0.elapsed().as_secs_f64() * 1000.0;
            eprintln!(
                "{ms:10.3} #{n} read {first}+{count} patience? {}: {:?}",
                roll < 130,
                got.as_ref().map(|w| w.first().copied())
            );
        }
        match got {
            Ok(words) => {
                assert_eq!(
                    words, expected,
                    "{case:?} seed {seed} (RACKD_WIRE_SEED={seed} replays it), request {n}: read of {count} \
                     word(s) at {first} answered with another request's data"
                );
                out.answered += 1;
            }
            Err(e) => {
                assert!(retryable(&e), "{case:?} seed {seed}, request {n}: read {first}+{count}: {e}");
                out.failed += 1;
            }
        }
    }
    let stats = plc.link_stats();
    out.timeouts = stats_before.0 + stats.timeouts;
    out.stale = stats_before.1 + stats.stale;
    out
}

/// Failures the weather may cause: a timeout, a reply spoilt on the way, a carrier lost.
fn retryable(e: &PlcError) -> bool {
    matches!(e, PlcError::Timeout { .. } | PlcError::Malformed(_) | PlcError::Connection(_))
}

/// Runs seeds `first..first + count` of `case`, each on its own paused runtime; returns
/// the outcomes summed.
pub(crate) fn seeds(case: Case, first: u64, count: u64, requests: u64) -> Outcome {
    let mut sum = Outcome::default();
    for seed in first..first + count {
        let runtime =
            tokio::runtime::Builder::new_current_thread().enable_all().start_paused(true).build().unwrap();
        let out = runtime.block_on(run(case, seed, requests));
        sum.reads += out.reads;
        sum.answered += out.answered;
        sum.failed += out.failed;
        sum.abandoned += out.abandoned;
        sum.restarts += out.restarts;
        sum.timeouts += out.timeouts;
        sum.stale += out.stale;
    }
    sum
}

fn env(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

/// The seeds the environment asks for, or the suite's.
fn range() -> (u64, u64, u64) {
    let requests = env("RACKD_WIRE_REQUESTS").unwrap_or(REQUESTS);
    match env("RACKD_WIRE_SEED") {
        Some(seed) => (seed, 1, requests),
        None => (env("RACKD_WIRE_FIRST").unwrap_or(0), env("RACKD_WIRE_SEEDS").unwrap_or(SEEDS), requests),
    }
}

/// Runs the environment's seeds of `case` and checks the run was not vacuous: most reads
/// answered, and the weather made the link time out and drop late replies.
fn check(case: Case) {
    let (first, count, requests) = range();
    let out = seeds(case, first, count, requests);
    eprintln!("{case:?}: seeds {first}..{}: {out:?}", first + count);
    assert!(out.answered * 10 >= out.reads * 6, "{case:?}: too few reads answered: {out:?}");
    if count * requests >= 10_000 {
        assert!(out.timeouts > 0 && out.restarts > 0 && out.abandoned > 0, "{case:?}: no fault met: {out:?}");
    }
}

macro_rules! cases {
    ($($name:ident: $case:ident,)*) => {
        $(
            #[test]
            fn $name() {
                check(Case::$case);
            }
        )*
    };
}

cases! {
    modbus_udp: ModbusUdp,
    modbus_udp_without_transaction_ids: ModbusUdpNoTid,
    modbus_tcp: ModbusTcp,
    modbus_tcp_without_transaction_ids: ModbusTcpNoTid,
    modbus_rtu_line: ModbusRtu,
    modbus_rtu_through_a_gateway: ModbusRtuGateway,
    mc3e_tcp: Mc3eTcp,
    mc3e_udp: Mc3eUdp,
    mc4e_tcp: Mc4eTcp,
    mc4e_udp: Mc4eUdp,
    mewtocol_line: Mewtocol,
    mewtocol_through_a_gateway: MewtocolGateway,
    ppi_line: Ppi,
    ppi_through_a_gateway: PpiGateway,
}
