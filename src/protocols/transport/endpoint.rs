//! Where a connection goes: a TCP peer, a UDP peer, a serial port, or a stream the caller
//! already opened; and what opening one gives (a byte stream or a datagram socket).
//!
//! RTU over TCP (a serial-to-Ethernet gateway) is [`Endpoint::Tcp`]: the carrier is a plain
//! TCP stream, and only the framing on top of it differs.

use std::io;
use std::net::SocketAddr;

use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::{TcpStream, UdpSocket};

use crate::capture::Transport;
use crate::protocols::serial::SerialSettings;

/// The two ends of an IP connection: its transport, rackd's end, the device's end.
pub(crate) type SocketPair = (Transport, SocketAddr, SocketAddr);

/// Any byte stream a link can run over (TCP socket, serial port, pty).
pub trait ByteStream: AsyncRead + AsyncWrite + Unpin + Send {}

impl<T: AsyncRead + AsyncWrite + Unpin + Send> ByteStream for T {}

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
}

impl std::fmt::Debug for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Endpoint::Tcp(address) => write!(f, "tcp {address}"),
            Endpoint::Udp { peer, .. } => write!(f, "udp {peer}"),
            Endpoint::Serial { path, settings } => write!(f, "serial {path} {settings}"),
            Endpoint::Given(_) => f.write_str("given stream"),
        }
    }
}

/// An open connection: a byte stream, or a UDP socket connected to its peer.
pub(crate) enum Carrier {
    /// TCP, a serial port or a given stream.
    Stream(Box<dyn ByteStream>),
    /// A UDP socket that only exchanges datagrams with the device.
    Datagram(UdpSocket),
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
                Ok(Carrier::Datagram(socket))
            }
            Endpoint::Serial { path, settings } => Ok(Carrier::Stream(Box::new(settings.open(path)?))),
            Endpoint::Given(stream) => stream.take().map(Carrier::Stream).ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::NotConnected,
                    "the given stream was closed and cannot be reopened",
                )
            }),
        }
    }
}
