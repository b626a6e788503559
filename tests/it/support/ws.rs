//! A WebSocket client for tests of `GET /api/v1/ws`.

use std::time::Duration;

use futures::{SinkExt, StreamExt};
use serde_json::Value;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// One subscriber.
pub struct Ws {
    stream: WebSocketStream<MaybeTlsStream<TcpStream>>,
}

/// What the server sent.
#[derive(Debug)]
pub enum Got {
    /// A JSON text message.
    Json(Value),
    /// A close frame with its code.
    Closed(u16),
    /// Nothing within the wait.
    Nothing,
    /// The connection ended without a close frame (a reset, or the server let go of it
    /// without a word): what the client saw. Only [`Ws::next_or_end`] answers it.
    Ended(String),
}

/// The `ws://` URL of `path` on a server at `base` (`http://...`).
pub fn url(base: &str, path: &str) -> String {
    format!("{}{path}", base.replacen("http://", "ws://", 1))
}

impl Ws {
    /// Connects to `/api/v1/ws` + `query` (e.g. `?topics=jobs`).
    pub async fn connect(base: &str, query: &str) -> Ws {
        Self::try_connect(base, query, None).await.expect("websocket connects")
    }

    /// Connects, optionally with an `Authorization: Bearer` header; the HTTP status on refusal.
    pub async fn try_connect(base: &str, query: &str, bearer: Option<&str>) -> Result<Ws, u16> {
        let auth = bearer.map(|key| format!("Bearer {key}"));
        let headers: Vec<(&str, &str)> = auth.iter().map(|a| ("authorization", a.as_str())).collect();
        Self::try_connect_with(base, query, &headers).await
    }

    /// Connects with these extra headers (`origin`, `host`, ...); the HTTP status on refusal.
    pub async fn try_connect_with(base: &str, query: &str, headers: &[(&str, &str)]) -> Result<Ws, u16> {
        let mut request = url(base, &format!("/api/v1/ws{query}")).into_client_request().unwrap();
        for (name, value) in headers {
            let name = tokio_tungstenite::tungstenite::http::HeaderName::from_bytes(name.as_bytes()).unwrap();
            request.headers_mut().insert(name, value.parse().unwrap());
        }
        match tokio_tungstenite::connect_async(request).await {
            Ok((stream, _)) => Ok(Ws { stream }),
            Err(tokio_tungstenite::tungstenite::Error::Http(response)) => Err(response.status().as_u16()),
            Err(e) => panic!("websocket connect: {e}"),
        }
    }

    /// Connects over a socket with a small receive buffer (a slow reader fills it quickly).
    pub async fn connect_small_buffer(base: &str, query: &str) -> Ws {
        let addr: std::net::SocketAddr = base.trim_start_matches("http://").parse().unwrap();
        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.set_recv_buffer_size(4096).unwrap();
        let tcp = socket.connect(addr).await.unwrap();
        let request = url(base, &format!("/api/v1/ws{query}")).into_client_request().unwrap();
        let (stream, _) = tokio_tungstenite::client_async(request, MaybeTlsStream::Plain(tcp)).await.unwrap();
        Ws { stream }
    }

    /// The next JSON message or close within `wait` (pings are answered and skipped); panics
    /// on a connection that ends without a close.
    pub async fn next(&mut self, wait: Duration) -> Got {
        match self.next_or_end(wait).await {
            Got::Ended(e) => panic!("websocket error: {e}"),
            got => got,
        }
    }

    /// As [`Ws::next`], with a connection that ends without a close as [`Got::Ended`], for a
    /// test that tells an end it caused from one it did not.
    pub async fn next_or_end(&mut self, wait: Duration) -> Got {
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            match tokio::time::timeout_at(deadline, self.stream.next()).await {
                Err(_) => return Got::Nothing,
                Ok(None) => return Got::Closed(1006),
                Ok(Some(Err(e))) => return Got::Ended(e.to_string()),
                Ok(Some(Ok(Message::Text(text)))) => {
                    return Got::Json(serde_json::from_str(&text).expect("messages are JSON"));
                }
                Ok(Some(Ok(Message::Close(frame)))) => {
                    return Got::Closed(frame.map(|f| u16::from(f.code)).unwrap_or(1005));
                }
                Ok(Some(Ok(_))) => continue,
            }
        }
    }

    /// The next JSON message; panics on anything else within 10 s.
    pub async fn json(&mut self) -> Value {
        match self.next(Duration::from_secs(10)).await {
            Got::Json(v) => v,
            other => panic!("expected a message, got {other:?}"),
        }
    }

    /// The next `n` events (messages with a `seq` and a `data`, not snapshots).
    pub async fn events(&mut self, n: usize) -> Vec<Value> {
        let mut out = Vec::with_capacity(n);
        while out.len() < n {
            let v = self.json().await;
            assert!(v["type"] != "snapshot" && v["type"] != "resync", "expected an event, got {v}");
            out.push(v);
        }
        out
    }

    /// Sends a ping and waits up to `wait` for its pong, passing over other messages.
    pub async fn ping(&mut self, wait: Duration) -> bool {
        self.stream.send(Message::Ping(b"are you there".to_vec().into())).await.unwrap();
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            match tokio::time::timeout_at(deadline, self.stream.next()).await {
                Ok(Some(Ok(Message::Pong(payload)))) => return payload.as_ref() == b"are you there",
                Ok(Some(Ok(_))) => continue,
                _ => return false,
            }
        }
    }

    /// Whether the server pings within `wait` (answered automatically, like a browser).
    pub async fn pinged(&mut self, wait: Duration) -> bool {
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            match tokio::time::timeout_at(deadline, self.stream.next()).await {
                Ok(Some(Ok(Message::Ping(_)))) => return true,
                Ok(Some(Ok(_))) => continue,
                _ => return false,
            }
        }
    }

    /// Closes politely.
    pub async fn close(mut self) {
        let _ = self.stream.send(Message::Close(None)).await;
    }
}
