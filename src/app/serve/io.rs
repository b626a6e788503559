//! What tells a connection's [`Conn`] what it is doing: its socket ([`Tracked`]: bytes in,
//! writes that do not go out), the service that hands each request to the router
//! ([`Service`]: headers parsed, a protocol switched) and each response's body
//! ([`Body`]: handed over in full).

use std::convert::Infallible;
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use axum::extract::ConnectInfo;
use bytes::Bytes;
use hyper::body::{Frame, Incoming, SizeHint};
use hyper::{Request, Response, StatusCode};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tower::ServiceExt;

use super::table::{Conn, Slot};

/// A client's socket, in clear or under TLS.
pub(super) enum Stream {
    /// HTTP.
    Plain(TcpStream),
    /// HTTPS (boxed: the TLS state is large and most of it is buffers).
    Tls(Box<tokio_rustls::server::TlsStream<TcpStream>>),
}

/// The socket as hyper (and, after an upgrade, a WebSocket) uses it; holds the
/// connection's place in the table until it is dropped, which closes it.
pub(super) struct Tracked {
    stream: Stream,
    conn: Arc<Conn>,
    _slot: Slot,
}

impl Tracked {
    pub(super) fn new(stream: Stream, conn: Arc<Conn>, slot: Slot) -> Tracked {
        Tracked { stream, conn, _slot: slot }
    }

    fn wrote<T>(&self, result: Poll<io::Result<T>>) -> Poll<io::Result<T>> {
        match &result {
            Poll::Pending => self.conn.write_blocked(),
            Poll::Ready(_) => self.conn.write_moved(),
        }
        result
    }
}

macro_rules! both {
    ($stream:expr, $s:ident => $call:expr) => {
        match $stream {
            Stream::Plain($s) => $call,
            Stream::Tls($s) => $call,
        }
    };
}

impl AsyncRead for Tracked {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let result = both!(&mut self.stream, s => Pin::new(s).poll_read(cx, buf));
        if matches!(result, Poll::Ready(Ok(()))) && buf.filled().len() > before {
            self.conn.heard();
        }
        result
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, data: &[u8]) -> Poll<io::Result<usize>> {
        let result = both!(&mut self.stream, s => Pin::new(s).poll_write(cx, data));
        self.wrote(result)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        data: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let result = both!(&mut self.stream, s => Pin::new(s).poll_write_vectored(cx, data));
        self.wrote(result)
    }

    fn is_write_vectored(&self) -> bool {
        both!(&self.stream, s => s.is_write_vectored())
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let result = both!(&mut self.stream, s => Pin::new(s).poll_flush(cx));
        self.wrote(result)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        both!(&mut self.stream, s => Pin::new(s).poll_shutdown(cx))
    }
}

/// Hands each request of one connection to the router, with the client's address as
/// axum's [`ConnectInfo`].
#[derive(Clone)]
pub(super) struct Service {
    pub(super) router: axum::Router,
    pub(super) conn: Arc<Conn>,
    pub(super) remote: SocketAddr,
}

/// The response future (boxed: the router's own future is boxed already, once more is
/// nothing beside a request's work).
type Responding = Pin<Box<dyn Future<Output = Result<Response<Body>, Infallible>> + Send>>;

impl hyper::service::Service<Request<Incoming>> for Service {
    type Response = Response<Body>;
    type Error = Infallible;
    type Future = Responding;

    fn call(&self, request: Request<Incoming>) -> Responding {
        self.conn.serving();
        let served = Served(self.conn.clone());
        let mut request = request.map(axum::body::Body::new);
        request.extensions_mut().insert(ConnectInfo(self.remote));
        let router = self.router.clone();
        Box::pin(async move {
            let Ok(response) = router.oneshot(request).await;
            if response.status() == StatusCode::SWITCHING_PROTOCOLS {
                served.0.upgraded();
            }
            Ok(response.map(|inner| Body { inner, _served: served }))
        })
    }
}

/// Marks the request served when dropped: when hyper has taken the whole body (or the
/// request was abandoned).
struct Served(Arc<Conn>);

impl Drop for Served {
    fn drop(&mut self) {
        self.0.served();
    }
}

/// A response body that tells its connection when it has been handed over.
pub(super) struct Body {
    inner: axum::body::Body,
    _served: Served,
}

impl hyper::body::Body for Body {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        hyper::body::Body::poll_frame(Pin::new(&mut self.inner), cx)
    }

    fn is_end_stream(&self) -> bool {
        hyper::body::Body::is_end_stream(&self.inner)
    }

    fn size_hint(&self) -> SizeHint {
        hyper::body::Body::size_hint(&self.inner)
    }
}
