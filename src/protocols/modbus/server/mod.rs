//! A Modbus server (slave) for simulators and tests, over UDP, TCP, RTU over TCP and RTU
//! on any byte stream (serial port, pty).
//!
//! ```no_run
//! # async fn demo() -> std::io::Result<()> {
//! use std::sync::Arc;
//! use rackd::protocols::faults::Faults;
//! use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerOptions};
//!
//! let bank = Bank::new();
//! bank.set_holding(4700, &[10000]);
//! // Answer like the shelf PLC: unit 1, MBAP length 0 in replies.
//! let options = ServerOptions { unit: 1, length0: true, ..ServerOptions::default() };
//! let server = ModbusServer::new(Arc::new(bank.clone()), options).serve_udp("127.0.0.1:0").await?;
//! println!("listening on {:?}", server.local_addr());
//! server.set_faults(Faults { drop_rate: 0.2, ..Faults::default() });
//! assert_eq!(bank.holding(4700, 1), vec![10000]);
//! server.shutdown().await;
//! # Ok(()) }
//! ```
//!
//! The bank is shared: whoever holds a [`Bank`] clone sees and changes what clients see. To
//! observe or veto requests, pass your own [`Handler`] that delegates to the bank.
//!
//! # Units
//!
//! Over RTU (serial or over TCP) the server is one station on a bus: it answers its own
//! unit, performs writes broadcast to unit 0 without replying, and ignores other units.
//! Over TCP and UDP (MBAP) the unit id addresses the device itself, so the server answers
//! its own unit (any of 0..=255) and also 0 and 255 as "this device": the Modbus Messaging
//! on TCP/IP Implementation Guide has a TCP device use 0xFF when the unit id is useless and
//! accept 0 for direct communication. A reply carries the request's unit id. Other units
//! are ignored, as a gateway with no station behind them would time out.

mod bank;
mod diagnostics;
mod handler;
mod rtu;
mod tcp;
mod udp;

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

pub use bank::{Bank, RegisterBank, TABLE_SIZE};
pub use handler::Handler;

use super::device_id::DeviceIdentification;
use super::exception::Exception;
use super::pdu::{Request, Response, encode_exception};
use crate::protocols::faults::{Faults, Plan, SharedFaults};
use crate::protocols::transport::{ByteStream, DatagramServerPort};

/// How a server presents itself.
#[derive(Clone, Debug, PartialEq)]
pub struct ServerOptions {
    /// The unit id it answers. Requests to other units are ignored, except: over RTU unit 0
    /// broadcasts (writes are performed without reply); over TCP and UDP units 0 and 255
    /// address this device and are answered (see the module documentation).
    pub unit: u8,
    /// Answer with an MBAP length field of 0, like the shelf PLC.
    pub length0: bool,
    /// Answer with transaction id 0 instead of echoing it (a PLC that does not echo).
    pub zero_transaction_id: bool,
    /// Faults to inject from the start.
    pub faults: Faults,
    /// The objects Read Device Identification (43 / 0x0E) is answered from, before the
    /// handler sees the request; rackd's own by default. `None` passes the request to the
    /// handler (a [`Bank`] answers exception 01, as a device without the function).
    pub identification: Option<DeviceIdentification>,
    /// Answer diagnostics (08) sub-functions 0002 and 000A..=000F from the server's own
    /// counters (see `diagnostics.rs`), before the handler sees them; `false` passes every
    /// sub-function to the handler (a device that has no counters).
    pub diagnostic_counters: bool,
}

impl Default for ServerOptions {
    fn default() -> Self {
        ServerOptions {
            unit: 1,
            length0: false,
            zero_transaction_id: false,
            faults: Faults::default(),
            identification: Some(DeviceIdentification::default()),
            diagnostic_counters: true,
        }
    }
}

/// Counters of a server's traffic.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ServerStats {
    /// Frames received that decoded as Modbus requests to any unit.
    pub requests: u64,
    /// Replies sent (duplicates counted once).
    pub replies: u64,
    /// Requests left unanswered by a drop fault.
    pub dropped: u64,
}

/// A server not yet listening: a handler and options.
pub struct ModbusServer {
    shared: Arc<Shared>,
}

/// What all connections of one server share.
pub(crate) struct Shared {
    handler: Arc<dyn Handler>,
    options: ServerOptions,
    faults: SharedFaults,
    requests: AtomicU64,
    replies: AtomicU64,
    dropped: AtomicU64,
    diagnostics: diagnostics::Counters,
}

/// A reply to send, and the faults to apply while sending it.
pub(crate) struct Outcome {
    pub unit: u8,
    pub pdu: Vec<u8>,
    pub plan: Plan,
}

/// How the framing a request came in addresses the server.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Addressing {
    /// MBAP (TCP, UDP): units 0 and 255 also mean this device; no broadcast.
    Mbap,
    /// RTU: a station on a bus; unit 0 broadcasts.
    Rtu,
}

impl Shared {
    /// Handles one request PDU sent to `unit`; `None` if no reply is due (another unit, a
    /// broadcast, a dropped request, a frame too short to answer).
    pub fn process(&self, unit: u8, pdu: &[u8], addressing: Addressing) -> Option<Outcome> {
        self.requests.fetch_add(1, Ordering::Relaxed);
        self.diagnostics.bus_message();
        let broadcast = unit == 0 && addressing == Addressing::Rtu;
        let this_device =
            unit == self.options.unit || (addressing == Addressing::Mbap && matches!(unit, 0 | 255));
        if !this_device && !broadcast {
            return None;
        }
        self.diagnostics.server_message();
        let plan = self.faults.plan();
        if plan.drop || plan.drop_ack {
            self.dropped.fetch_add(1, Ordering::Relaxed);
            self.diagnostics.no_response();
            return None;
        }
        let function = *pdu.first()?;
        let result = match Request::decode(pdu) {
            Ok(req) if broadcast && !req.is_write() => {
                self.diagnostics.no_response();
                return None;
            }
            // A Modbus exception is one byte: the code's low byte.
            Ok(req) => match plan.device_error {
                Some(code) => Err(Exception(code as u8)),
                None => self.own_answer(&req).unwrap_or_else(|| self.handler.handle(unit, &req)),
            },
            Err(e) => {
                self.diagnostics.undecoded(e);
                Err(e.exception())
            }
        };
        if broadcast {
            self.diagnostics.no_response();
            return None;
        }
        if result.is_err() {
            self.diagnostics.exception();
        }
        let mut out = Vec::with_capacity(260);
        match result {
            Ok(response) => response.encode(&mut out),
            Err(e) => encode_exception(function, e.0, &mut out),
        }
        Some(Outcome { unit: plan.wrong_unit.unwrap_or(unit), pdu: out, plan })
    }

    /// The answer the server gives itself, before the handler: device identification from
    /// its options, diagnostics from its counters; `None` for the handler to answer.
    fn own_answer(&self, request: &Request) -> Option<Result<Response, Exception>> {
        match request {
            Request::ReadDeviceId { code, object_id } => {
                let objects = self.options.identification.as_ref()?;
                Some(objects.answer(*code, *object_id).map(Response::ReadDeviceId))
            }
            Request::Diagnostics { sub_function, data } if self.options.diagnostic_counters => {
                self.diagnostics.answer(*sub_function, *data).map(Ok)
            }
            _ => None,
        }
    }

    pub fn replied(&self) {
        self.replies.fetch_add(1, Ordering::Relaxed);
    }
}

impl ModbusServer {
    /// A server that answers with `handler` (usually a [`Bank`]).
    pub fn new(handler: Arc<dyn Handler>, options: ServerOptions) -> Self {
        let faults = SharedFaults::new(options.faults.clone());
        let shared = Shared {
            handler,
            options,
            faults,
            requests: AtomicU64::new(0),
            replies: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            diagnostics: diagnostics::Counters::default(),
        };
        ModbusServer { shared: Arc::new(shared) }
    }

    /// Serves Modbus UDP on `address` (`127.0.0.1:0` picks a free port).
    pub async fn serve_udp(self, address: &str) -> std::io::Result<ServerHandle> {
        let socket = tokio::net::UdpSocket::bind(address).await?;
        let local = socket.local_addr()?;
        let task = tokio::spawn(udp::serve(Box::new(socket), self.shared.clone()));
        Ok(ServerHandle { local_addr: Some(local), shared: self.shared, task })
    }

    /// Serves Modbus UDP frames on a serving datagram `port` the caller bound (a simulated
    /// one, in the seeded wire simulation of the tests).
    pub fn serve_datagrams(&self, port: impl DatagramServerPort) -> ServerHandle {
        self.serve_boxed_datagrams(Box::new(port))
    }

    /// As [`ModbusServer::serve_datagrams`], for a port already boxed.
    pub fn serve_boxed_datagrams(&self, port: Box<dyn DatagramServerPort>) -> ServerHandle {
        let task = tokio::spawn(udp::serve(port, self.shared.clone()));
        ServerHandle { local_addr: None, shared: self.shared.clone(), task }
    }

    /// Serves Modbus TCP (MBAP) frames on one connection the caller opened.
    pub fn serve_mbap_stream(&self, stream: impl ByteStream + 'static) -> ServerHandle {
        let task = tokio::spawn(tcp::serve_mbap(Box::new(stream), self.shared.clone()));
        ServerHandle { local_addr: None, shared: self.shared.clone(), task }
    }

    /// Serves Modbus TCP on `address`.
    pub async fn serve_tcp(self, address: &str) -> std::io::Result<ServerHandle> {
        self.serve_tcp_on(tokio::net::TcpListener::bind(address).await?)
    }

    /// Serves Modbus TCP on a `listener` the caller bound (a test that keeps the port
    /// while the PLC is off, to start it again there).
    pub fn serve_tcp_on(self, listener: tokio::net::TcpListener) -> std::io::Result<ServerHandle> {
        let local = listener.local_addr()?;
        let task = tokio::spawn(tcp::serve(listener, self.shared.clone(), tcp::Framing::Mbap));
        Ok(ServerHandle { local_addr: Some(local), shared: self.shared, task })
    }

    /// Serves Modbus RTU frames over raw TCP on `address` (as a serial-to-Ethernet gateway).
    pub async fn serve_rtu_over_tcp(self, address: &str) -> std::io::Result<ServerHandle> {
        let listener = tokio::net::TcpListener::bind(address).await?;
        let local = listener.local_addr()?;
        let task = tokio::spawn(tcp::serve(listener, self.shared.clone(), tcp::Framing::Rtu));
        Ok(ServerHandle { local_addr: Some(local), shared: self.shared, task })
    }

    /// Serves Modbus RTU on a stream already open (a serial port, one end of a pty pair);
    /// `baud` sets the inter-frame silence (0 for the 1.75 ms floor).
    pub fn serve_rtu_stream(&self, stream: impl ByteStream + 'static, baud: u32) -> ServerHandle {
        let task = tokio::spawn(rtu::serve(Box::new(stream), self.shared.clone(), baud));
        ServerHandle { local_addr: None, shared: self.shared.clone(), task }
    }
}

/// A running server. Dropping it stops the server (and closes its connections).
pub struct ServerHandle {
    local_addr: Option<SocketAddr>,
    shared: Arc<Shared>,
    task: tokio::task::JoinHandle<()>,
}

impl ServerHandle {
    /// The bound socket address (`None` for a stream server).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// Replaces the standing faults; applies from the next request on.
    pub fn set_faults(&self, faults: Faults) {
        self.shared.faults.set(faults);
    }

    /// The server's faults, to script one-off faults or change them in place.
    pub fn faults(&self) -> SharedFaults {
        self.shared.faults.clone()
    }

    /// Traffic counters so far.
    pub fn stats(&self) -> ServerStats {
        ServerStats {
            requests: self.shared.requests.load(Ordering::Relaxed),
            replies: self.shared.replies.load(Ordering::Relaxed),
            dropped: self.shared.dropped.load(Ordering::Relaxed),
        }
    }

    /// Stops the server, closes its socket and every connection, and waits until it has.
    pub async fn shutdown(mut self) {
        self.task.abort();
        let _ = (&mut self.task).await;
    }

    /// Runs until the server stops by itself (a stream server whose stream closed).
    pub async fn wait(mut self) {
        let _ = (&mut self.task).await;
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        self.task.abort();
    }
}
