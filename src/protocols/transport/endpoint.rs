//! Where a connection goes: a TCP peer, a UDP peer, a serial port, or a stream the caller
//! already opened; and what opening one gives (a byte stream or a datagram socket).
//!
//! RTU over TCP (a serial-to-Ethernet gateway) is [`Endpoint::Tcp`]: the carrier is a plain
//! TCP stream, and only the framing on top of it differs.
//!
//! A datagram carrier is a [`DatagramPort`] (a UDP socket, or a simulated one), so the links
//! run over a caller's carriers as they do over the operating system's: [`Endpoint::Dial`]
//! opens one each time the link asks (the seeded wire simulation of the tests dials its own
//! streams and datagram ports this way).

use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpStream, UdpSocket};

use crate::capture::Transport;
use crate::protocols::serial::SerialSettings;

/// The two ends of an IP connection: its transport, rackd's end, the device's end.
pub(crate) type SocketPair = (Transport, SocketAddr, SocketAddr);

/// Any byte stream a link can run over (TCP socket, serial port, pty).
pub trait ByteStream: AsyncRead + AsyncWrite + Unpin + Send {}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> ByteStream for T {}

/// A datagram socket connected to one peer: a UDP socket, or a simulated one.
pub trait DatagramPort: Send + Sync {
    /// Sends one datagram to the peer.
    fn poll_send(&self, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>>;
    /// Receives one datagram from the peer into `buf` (cut to its room).
    fn poll_recv(&self, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>>;
    /// Receives a datagram already waiting, or fails with [`io::ErrorKind::WouldBlock`].
    fn try_recv(&self, buf: &mut [u8]) -> io::Result<usize>;
    /// This end's address.
    fn local_addr(&self) -> io::Result<SocketAddr>;
    /// The peer's address.
    fn peer_addr(&self) -> io::Result<SocketAddr>;
}

impl DatagramPort for UdpSocket {
    fn poll_send(&self, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        UdpSocket::poll_send(self, cx, buf)
    }

    fn poll_recv(&self, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        UdpSocket::poll_recv(self, cx, buf)
    }

    fn try_recv(&self, buf: &mut [u8]) -> io::Result<usize> {
        UdpSocket::try_recv(self, buf)
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        UdpSocket::local_addr(self)
    }

    fn peer_addr(&self) -> io::Result<SocketAddr> {
        UdpSocket::peer_addr(self)
    }
}

/// The serving end of datagrams: a UDP socket bound to the server's address, or a
/// simulated one; requests come from any peer, answers go to the peer named.
pub trait DatagramServerPort: Send + Sync + 'static {
    /// Receives one datagram into `buf` and says whom it came from.
    fn poll_recv_from(&self, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<SocketAddr>>;
    /// Sends one datagram to `target`.
    fn poll_send_to(&self, cx: &mut Context<'_>, buf: &[u8], target: SocketAddr) -> Poll<io::Result<usize>>;
}

impl DatagramServerPort for UdpSocket {
    fn poll_recv_from(&self, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<SocketAddr>> {
        UdpSocket::poll_recv_from(self, cx, buf)
    }

    fn poll_send_to(&self, cx: &mut Context<'_>, buf: &[u8], target: SocketAddr) -> Poll<io::Result<usize>> {
        UdpSocket::poll_send_to(self, cx, buf, target)
    }
}

/// Receives one datagram on a serving `port`: its length and sender.
pub async fn recv_from(port: &dyn DatagramServerPort, buf: &mut [u8]) -> io::Result<(usize, SocketAddr)> {
    let mut read = ReadBuf::new(buf);
    let from = std::future::poll_fn(|cx| port.poll_recv_from(cx, &mut read)).await?;
    Ok((read.filled().len(), from))
}

/// Sends one datagram from a serving `port` to `target`.
pub async fn send_to(port: &dyn DatagramServerPort, buf: &[u8], target: SocketAddr) -> io::Result<usize> {
    std::future::poll_fn(|cx| port.poll_send_to(cx, buf, target)).await
}

/// A carrier being opened by a [`Dial`].
pub type Dialing = Pin<Box<dyn Future<Output = io::Result<Carrier>> + Send>>;

/// Opens carriers on demand, for [`Endpoint::Dial`].
pub trait Dial: Send + Sync {
    /// Opens a new carrier: a new connection or datagram port, or the same line again.
    fn dial(&self) -> Dialing;
}

/// Where a connection goes.
pub enum Endpoint {
    /// A TCP connection to `HOST:PORT` (also RTU over TCP, and the line protocols through a
    /// serial-to-Ethernet gateway).
    Tcp(String),
    /// UDP datagrams to `HOST:PORT`, from `local` or a fresh ephemeral port.
    Udp {
        /// The device's `HOST:PORT`.
        peer: String,
        /// A fixed local address (some Ethernet modules only answer a configured port).
        local: Option<SocketAddr>,
    },
    /// A serial port opened with these settings.
    Serial {
        /// The device path (`/dev/ttyUSB0`).
        path: String,
        /// Baud rate and character format.
        settings: SerialSettings,
    },
    /// A stream handed over by the caller (a pty in tests); it cannot be reopened once lost.
    Given(Option<Box<dyn ByteStream>>),
    /// Carriers the caller opens, as often as the link asks (a simulated wire).
    Dial(Arc<dyn Dial>),
}

impl std::fmt::Debug for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Endpoint::Tcp(address) => write!(f, "tcp {address}"),
            Endpoint::Udp { peer, .. } => write!(f, "udp {peer}"),
            Endpoint::Serial { path, settings } => write!(f, "serial {path} {settings}"),
            Endpoint::Given(_) => f.write_str("given stream"),
            Endpoint::Dial(_) => f.write_str("dialled carrier"),
        }
    }
}

/// An open connection: a byte stream, or a datagram port connected to its peer.
pub enum Carrier {
    /// TCP, a serial port or a given stream.
    Stream(Box<dyn ByteStream>),
    /// A UDP socket (or a simulated one) that only exchanges datagrams with the device.
    Datagram(Box<dyn DatagramPort>),
}

impl Endpoint {
    /// A stream endpoint for the caller's own stream.
    pub fn given(stream: impl ByteStream + 'static) -> Endpoint {
        Endpoint::Given(Some(Box::new(stream)))
    }

    /// Opens the endpoint; with the carrier, the socket pair of an IP one (rackd's end
    /// first), for the flight recorder.
    pub(crate) async fn open(&mut self) -> io::Result<(Carrier, Option<SocketPair>)> {
        if let Endpoint::Tcp(address) = self {
            let stream = TcpStream::connect(address.as_str()).await?;
            stream.set_nodelay(true)?;
            let pair = (Transport::Tcp, stream.local_addr()?, stream.peer_addr()?);
            return Ok((Carrier::Stream(Box::new(stream)), Some(pair)));
        }
        let carrier = self.open_other().await?;
        let pair = match &carrier {
            Carrier::Datagram(socket) => Some((Transport::Udp, socket.local_addr()?, socket.peer_addr()?)),
            Carrier::Stream(_) => None,
        };
        Ok((carrier, pair))
    }

    /// Opens an endpoint other than TCP.
    async fn open_other(&mut self) -> io::Result<Carrier> {
        match self {
            Endpoint::Tcp(_) => Err(io::Error::other("TCP is opened by `open`")),
            Endpoint::Udp { peer, local } => {
                let peer = tokio::net::lookup_host(peer.as_str())
                    .await?
                    .next()
                    .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "address resolves to nothing"))?;
                let local = local.unwrap_or_else(|| match peer {
                    SocketAddr::V4(_) => SocketAddr::from(([0, 0, 0, 0], 0)),
                    SocketAddr::V6(_) => SocketAddr::from(([0u16; 8], 0)),
                });
                let socket = UdpSocket::bind(local).await?;
                // A connected socket: the kernel drops datagrams from anyone but the device.
                socket.connect(peer).await?;
                Ok(Carrier::Datagram(Box::new(socket)))
            }
            Endpoint::Serial { path, settings } => Ok(Carrier::Stream(Box::new(settings.open(path)?))),
            Endpoint::Given(stream) => stream.take().map(Carrier::Stream).ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::NotConnected,
                    "the given stream was closed and cannot be reopened",
                )
            }),
            Endpoint::Dial(dial) => dial.dial().await,
        }
    }
}
