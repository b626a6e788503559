//! The server side of byte-stream protocols (MEWTOCOL, PPI): a running server over TCP
//! connections or over one stream (a serial port, a pty), and the TCP accept loop.

use std::future::Future;
use std::net::SocketAddr;

use tokio::net::{TcpListener, TcpStream};
use tokio::task::{JoinHandle, JoinSet};

/// A running server; dropping it (or [`StreamServer::shutdown`]) stops it and closes its
/// connections.
pub struct StreamServer {
    local_addr: Option<SocketAddr>,
    task: JoinHandle<()>,
}

impl StreamServer {
    /// A server running as `task`, listening on `local_addr` (None for a single stream).
    pub(crate) fn new(local_addr: Option<SocketAddr>, task: JoinHandle<()>) -> Self {
        StreamServer { local_addr, task }
    }

    /// The TCP address served, if any.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// Serves until the process ends (for standalone simulators).
    pub async fn run_forever(mut self) {
        let _ = (&mut self.task).await;
    }

    /// Stops the server.
    pub async fn shutdown(mut self) {
        self.task.abort();
        let _ = (&mut self.task).await;
    }
}

impl Drop for StreamServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Binds `addr` and serves every accepted connection with `serve`.
pub(crate) async fn spawn_tcp<F, Fut>(addr: &str, serve: F) -> std::io::Result<StreamServer>
where
    F: Fn(TcpStream) -> Fut + Send + 'static,
    Fut: Future<Output = ()> + Send + 'static,
{
    let listener = TcpListener::bind(addr).await?;
    let local_addr = listener.local_addr()?;
    let task = tokio::spawn(async move {
        // Connection tasks live in the set, so aborting this task closes them all.
        let mut connections = JoinSet::new();
        loop {
            tokio::select! {
                accepted = listener.accept() => match accepted {
                    Ok((stream, _)) => {
                        let _ = stream.set_nodelay(true);
                        connections.spawn(serve(stream));
                    }
                    Err(e) => tracing::warn!(error = %e, "stream server: accept failed"),
                },
                Some(_) = connections.join_next(), if !connections.is_empty() => {}
            }
        }
    });
    Ok(StreamServer::new(Some(local_addr), task))
}
