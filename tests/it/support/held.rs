//! A loopback TCP port a test keeps while the server on it stops and starts again (a PLC
//! switched off and on, a webhook receiver that goes down, a rackd restarted under the page
//! that watches it), or that nothing ever listens on.
//!
//! Between two lives of the server the port is held by a socket that is bound and does not
//! listen: a connection to it is refused, as by a stopped server, and nothing else can take
//! the port. A port let go and bound again can be taken in between, by another test's
//! server or as the local port of any outgoing connection (an HTTP client's, a device
//! link's), and the restart then fails with "Address already in use", as the suite once did
//! on a busy machine.
//!
//! Every socket on the port sets `SO_REUSEPORT`: the one way for two TCP sockets to share
//! a port on Linux, open only to sockets of the same user that all set it (rackd sets it
//! nowhere). The kernel never gives a port in use to a bind of port 0 or to an outgoing
//! connection.

use std::net::SocketAddr;

use tokio::net::{TcpListener, TcpSocket};

/// A loopback port held for the test's servers (see the module doc).
pub struct HeldPort {
    addr: SocketAddr,
    _holder: TcpSocket,
}

impl HeldPort {
    /// A port of the kernel's choosing on 127.0.0.1, held: nothing listens on it yet.
    pub fn new() -> HeldPort {
        let holder = socket();
        holder.bind("127.0.0.1:0".parse().unwrap()).expect("binding a held port");
        let addr = holder.local_addr().unwrap();
        HeldPort { addr, _holder: holder }
    }

    /// Its address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// A listener on the port for the server's next life (drop it to stop listening: the
    /// port stays held). Inside a Tokio runtime.
    pub fn listen(&self) -> TcpListener {
        let socket = socket();
        socket.bind(self.addr).unwrap_or_else(|e| panic!("listening on the held port {}: {e}", self.addr));
        socket.listen(1024).unwrap()
    }
}

/// A socket that shares its port with the others of the held port only: `SO_REUSEPORT`,
/// and not `SO_REUSEADDR` (which would let any other socket with it, a server of the
/// standard library's, say, bind the port while only the holder has it, not listening).
fn socket() -> TcpSocket {
    let socket = TcpSocket::new_v4().unwrap();
    socket.set_reuseport(true).unwrap();
    socket
}
