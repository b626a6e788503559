//! An MC 3E binary server over TCP or UDP, for simulators and tests.
//!
//! The server answers 3E and 4E frames on the same port (batch reads and writes, random and
//! block reads, the CPU model name) against a [`SharedBank`] and injects the
//! faults of a [`SharedFaults`]; both handles stay with the caller, who may read and change
//! them while the server runs. A write hook ([`WriteHook`]) is called after each write.
//!
//! ```no_run
//! # async fn demo() -> std::io::Result<()> {
//! use rackd::protocols::faults::Fault;
//! use rackd::protocols::mc3e::{Bank, Device, Mc3eServer, ServerState};
//! let state = ServerState::new(Bank::default().shared());
//! let server = Mc3eServer::bind_udp("127.0.0.1:0".parse().unwrap(), state).await?;
//! server.bank().lock().unwrap().set_word(Device::D, 200, 1);
//! server.faults().push(Fault::Drop);
//! server.shutdown().await;
//! # Ok(()) }
//! ```

use std::net::SocketAddr;
use std::sync::Arc;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, UdpSocket};
use tokio::task::{JoinHandle, JoinSet};

use super::bank::SharedBank;
use super::frame::{self, Direction};
use super::handler::{self, WriteHook};
use super::type_name::TypeName;
use crate::protocols::faults::{Plan, SharedFaults};
use crate::protocols::transport::{ByteStream, DatagramServerPort, recv_from, send_to};

/// What a server serves: memory, faults and an optional write hook.
#[derive(Clone)]
pub struct ServerState {
    /// The device memory.
    pub bank: SharedBank,
    /// The fault settings.
    pub faults: SharedFaults,
    /// Called after every successful write.
    pub on_write: Option<WriteHook>,
    /// What "read CPU model name" answers (default: Q03UDVCPU, 0x0366).
    pub type_name: TypeName,
}

impl ServerState {
    /// A state serving `bank`, without faults or hook.
    pub fn new(bank: SharedBank) -> Self {
        ServerState { bank, faults: SharedFaults::default(), on_write: None, type_name: TypeName::default() }
    }

    /// The same state answering "read CPU model name" with `type_name`.
    pub fn with_type_name(mut self, type_name: TypeName) -> Self {
        self.type_name = type_name;
        self
    }

    /// The same state with these faults.
    pub fn with_faults(mut self, faults: SharedFaults) -> Self {
        self.faults = faults;
        self
    }

    /// The same state with a write hook.
    pub fn on_write(mut self, hook: WriteHook) -> Self {
        self.on_write = Some(hook);
        self
    }

    /// The faults to apply to one frame, and its answer, if any. A wrong id changes a 4E
    /// reply's serial number (3E frames have none); wrong units do not apply (no unit).
    fn process(&self, bytes: &[u8]) -> (Plan, Option<Vec<u8>>) {
        let plan = self.faults.plan();
        if plan.unanswered() {
            return (plan, None);
        }
        let answer = handler::answer(&self.bank, &self.type_name, bytes, plan.device_error);
        if let (Some(hook), Some(write)) = (&self.on_write, answer.as_ref().and_then(|a| a.write)) {
            hook(write);
        }
        let mut bytes = answer.map(|a| a.bytes);
        if let Some(reply) =
            bytes.as_mut().filter(|r| plan.wrong_id && r.starts_with(&frame::RESPONSE_SUBHEADER_4E))
        {
            let serial = u16::from_le_bytes([reply[2], reply[3]]).wrapping_add(1);
            reply[2..4].copy_from_slice(&serial.to_le_bytes());
        }
        (plan, bytes)
    }
}

/// A running server; dropping it (or [`Mc3eServer::shutdown`]) stops it and closes every
/// connection.
pub struct Mc3eServer {
    local_addr: SocketAddr,
    state: ServerState,
    task: JoinHandle<()>,
}

impl Mc3eServer {
    /// Listens for TCP connections on `addr` (port 0 picks a free port).
    pub async fn bind_tcp(addr: SocketAddr, state: ServerState) -> std::io::Result<Mc3eServer> {
        let listener = TcpListener::bind(addr).await?;
        let local_addr = listener.local_addr()?;
        let task = tokio::spawn(serve_tcp(listener, state.clone()));
        Ok(Mc3eServer { local_addr, state, task })
    }

    /// Serves UDP datagrams on `addr` (port 0 picks a free port).
    pub async fn bind_udp(addr: SocketAddr, state: ServerState) -> std::io::Result<Mc3eServer> {
        let socket = UdpSocket::bind(addr).await?;
        let local_addr = socket.local_addr()?;
        let task = tokio::spawn(serve_udp(Arc::new(socket), state.clone()));
        Ok(Mc3eServer { local_addr, state, task })
    }

    /// Serves datagrams on a serving `port` the caller bound (a simulated one, in the
    /// seeded wire simulation of the tests); `local_addr` names it.
    pub fn serve_datagrams(
        port: impl DatagramServerPort,
        local_addr: SocketAddr,
        state: ServerState,
    ) -> Mc3eServer {
        let task = tokio::spawn(serve_udp(Arc::new(port), state.clone()));
        Mc3eServer { local_addr, state, task }
    }

    /// Serves one connection the caller opened; the task ends when it closes.
    pub fn serve_stream(
        stream: impl ByteStream + 'static,
        peer: SocketAddr,
        state: ServerState,
    ) -> JoinHandle<()> {
        tokio::spawn(serve_connection(Box::new(stream), peer, state))
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.local_addr
    }

    /// The served memory.
    pub fn bank(&self) -> SharedBank {
        self.state.bank.clone()
    }

    /// The fault settings.
    pub fn faults(&self) -> SharedFaults {
        self.state.faults.clone()
    }

    /// Serves until the process ends (for standalone simulators).
    pub async fn run_forever(mut self) {
        let _ = (&mut self.task).await;
    }

    /// Stops the server and closes its connections and socket.
    pub async fn shutdown(mut self) {
        self.task.abort();
        let _ = (&mut self.task).await;
    }
}

impl Drop for Mc3eServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn serve_tcp(listener: TcpListener, state: ServerState) {
    // Connection tasks live in the set, so aborting this task drops (closes) them all.
    let mut connections = JoinSet::new();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    let _ = stream.set_nodelay(true);
                    connections.spawn(serve_connection(Box::new(stream), peer, state.clone()));
                }
                Err(e) => tracing::warn!(error = %e, "mc3e server: accept failed"),
            },
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
        }
    }
}

/// Serves one connection, one request at a time, like a PLC's Ethernet port; 3E and 4E
/// frames may alternate. Bytes that are not a 3E or 4E request leave the stream impossible
/// to resynchronise, so the connection closes.
async fn serve_connection(mut stream: Box<dyn ByteStream>, peer: SocketAddr, state: ServerState) {
    let mut frame_bytes = Vec::new();
    loop {
        let mut header = [0u8; frame::HEADER_LEN_4E];
        if stream.read_exact(&mut header[..2]).await.is_err() {
            return;
        }
        let Ok(size) = frame::header_size_of(&header, Direction::Request) else {
            tracing::debug!(%peer, "mc3e server: not a 3E/4E binary request, closing");
            return;
        };
        if stream.read_exact(&mut header[2..size]).await.is_err() {
            return;
        }
        let Ok(parsed) = frame::parse_any_header(&header[..size], Direction::Request) else { return };
        frame_bytes.clear();
        frame_bytes.extend_from_slice(&header[..size]);
        frame_bytes.resize(size + parsed.length, 0);
        if stream.read_exact(&mut frame_bytes[size..]).await.is_err() {
            return;
        }
        let (plan, out) = state.process(&frame_bytes);
        if plan.close {
            return;
        }
        if !plan.delay.is_zero() {
            tokio::time::sleep(plan.delay).await;
        }
        let Some(answer) = out else { continue };
        let mut out = plan.garbage.unwrap_or_default();
        out.extend_from_slice(&answer);
        if plan.duplicate {
            out.extend_from_slice(&answer);
        }
        if stream.write_all(&out).await.is_err() {
            return;
        }
    }
}

async fn serve_udp<S: DatagramServerPort>(socket: Arc<S>, state: ServerState) {
    let mut buf = vec![0u8; 65_536];
    // Delayed replies live in the set, so stopping the server cancels them too.
    let mut delayed = JoinSet::new();
    loop {
        let received = tokio::select! {
            received = recv_from(socket.as_ref(), &mut buf) => received,
            Some(_) = delayed.join_next(), if !delayed.is_empty() => continue,
        };
        let (len, peer) = match received {
            Ok(received) => received,
            Err(e) => {
                // ICMP "port unreachable" from an earlier reply surfaces here on some systems.
                tracing::debug!(error = %e, "mc3e server: recv failed");
                continue;
            }
        };
        let (plan, Some(answer)) = state.process(&buf[..len]) else { continue };
        // Each piece is its own datagram: the noise, the answer, its duplicate.
        let mut datagrams: Vec<Vec<u8>> = plan.garbage.into_iter().collect();
        datagrams.push(answer.clone());
        if plan.duplicate {
            datagrams.push(answer);
        }
        if plan.delay.is_zero() {
            for datagram in &datagrams {
                let _ = send_to(socket.as_ref(), datagram, peer).await;
            }
            continue;
        }
        let socket = socket.clone();
        delayed.spawn(async move {
            tokio::time::sleep(plan.delay).await;
            for datagram in &datagrams {
                let _ = send_to(socket.as_ref(), datagram, peer).await;
            }
        });
    }
}
