//! The simulated carriers: datagram ports (the client's and the device's), streams, and the
//! dials that open them for a link.

use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

use super::{DEVICE, To, Wire};
use crate::protocols::transport::{Carrier, DatagramPort, DatagramServerPort, Dial, Dialing};

/// What the device does with a new connection (spawns a server on it).
pub type Accept = Arc<dyn Fn(SimStream) + Send + Sync>;

fn client_addr(port: u16) -> SocketAddr {
    SocketAddr::from(([10, 0, 0, 1], port))
}

/// Binds a new datagram port for each dial.
pub(super) struct DatagramDial(pub Wire);

impl Dial for DatagramDial {
    fn dial(&self) -> Dialing {
        let port = self.0.net().bind();
        let sim = SimPort { wire: self.0.clone(), port };
        Box::pin(async move { Ok(Carrier::Datagram(Box::new(sim))) })
    }
}

/// A client's datagram port, connected to the device; dropping it lets the number go.
struct SimPort {
    wire: Wire,
    port: u16,
}

impl DatagramPort for SimPort {
    fn poll_send(&self, _cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        self.wire.send(To::Server(self.port), buf);
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_recv(&self, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let mut net = self.wire.net();
        let Some(inbox) = net.ports.get_mut(&self.port) else {
            return Poll::Ready(Err(io::ErrorKind::NotConnected.into()));
        };
        match inbox.items.pop_front() {
            Some(datagram) => {
                let n = datagram.len().min(buf.remaining());
                buf.put_slice(&datagram[..n]);
                Poll::Ready(Ok(()))
            }
            None => {
                inbox.waker = Some(cx.waker().clone());
                Poll::Pending
            }
        }
    }

    fn try_recv(&self, buf: &mut [u8]) -> io::Result<usize> {
        let mut net = self.wire.net();
        let inbox = net.ports.get_mut(&self.port).ok_or(io::ErrorKind::NotConnected)?;
        let datagram = inbox.items.pop_front().ok_or(io::ErrorKind::WouldBlock)?;
        let n = datagram.len().min(buf.len());
        buf[..n].copy_from_slice(&datagram[..n]);
        Ok(n)
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        Ok(client_addr(self.port))
    }

    fn peer_addr(&self) -> io::Result<SocketAddr> {
        Ok(DEVICE)
    }
}

impl Drop for SimPort {
    fn drop(&mut self) {
        self.wire.net().ports.remove(&self.port);
    }
}

/// The device's datagram port: requests from every client port, answers to any.
pub struct SimServerPort(pub Wire);

impl DatagramServerPort for SimServerPort {
    fn poll_recv_from(&self, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<SocketAddr>> {
        let mut net = self.0.net();
        match net.server.items.pop_front() {
            Some((from, datagram)) => {
                let n = datagram.len().min(buf.remaining());
                buf.put_slice(&datagram[..n]);
                Poll::Ready(Ok(client_addr(from)))
            }
            None => {
                net.server.waker = Some(cx.waker().clone());
                Poll::Pending
            }
        }
    }

    fn poll_send_to(&self, _cx: &mut Context<'_>, buf: &[u8], target: SocketAddr) -> Poll<io::Result<usize>> {
        self.0.send(To::Port(target.port()), buf);
        Poll::Ready(Ok(buf.len()))
    }
}

/// Opens a new connection for each dial and hands the device's end to `accept`.
pub(super) struct ConnectionDial {
    pub wire: Wire,
    pub accept: Accept,
}

impl Dial for ConnectionDial {
    fn dial(&self) -> Dialing {
        let conn = self.wire.open_stream();
        (self.accept)(SimStream::new(self.wire.clone(), conn, 1, true));
        let client = SimStream::new(self.wire.clone(), conn, 0, true);
        Box::pin(async move { Ok(Carrier::Stream(Box::new(client))) })
    }
}

/// Reaches the client's end of the same line at every dial.
pub(super) struct LineDial {
    pub wire: Wire,
    pub conn: usize,
}

impl Dial for LineDial {
    fn dial(&self) -> Dialing {
        let client = SimStream::new(self.wire.clone(), self.conn, 0, false);
        Box::pin(async move { Ok(Carrier::Stream(Box::new(client))) })
    }
}

/// One end of a simulated stream. A connection's end closes when dropped; a line's never
/// does (the next dial reaches it again).
pub struct SimStream {
    wire: Wire,
    conn: usize,
    end: usize,
    closes: bool,
}

impl SimStream {
    pub(super) fn new(wire: Wire, conn: usize, end: usize, closes: bool) -> SimStream {
        SimStream { wire, conn, end, closes }
    }
}

impl AsyncRead for SimStream {
    fn poll_read(self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let mut net = self.wire.net();
        let end = &mut net.streams[self.conn][self.end];
        if end.inbox.items.is_empty() {
            if end.eof {
                return Poll::Ready(Ok(()));
            }
            end.inbox.waker = Some(cx.waker().clone());
            return Poll::Pending;
        }
        let n = end.inbox.items.len().min(buf.remaining());
        let (a, b) = end.inbox.items.as_slices();
        let first = a.len().min(n);
        buf.put_slice(&a[..first]);
        buf.put_slice(&b[..n - first]);
        end.inbox.items.drain(..n);
        Poll::Ready(Ok(()))
    }
}

impl AsyncWrite for SimStream {
    fn poll_write(self: Pin<&mut Self>, _cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        if self.wire.net().streams[self.conn][self.end].closed {
            return Poll::Ready(Err(io::ErrorKind::BrokenPipe.into()));
        }
        self.wire.send(To::End(self.conn, 1 - self.end), buf);
        Poll::Ready(Ok(buf.len()))
    }

    fn poll_flush(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }

    fn poll_shutdown(self: Pin<&mut Self>, _cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Poll::Ready(Ok(()))
    }
}

impl Drop for SimStream {
    fn drop(&mut self) {
        if self.closes {
            self.wire.close(self.conn, self.end);
        }
    }
}
