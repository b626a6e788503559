//! Building and running the service: bind, serve, shut down gracefully.

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;

use crate::api::metrics::Metrics;
use crate::api::{self, AppState};
use crate::auth::KeyRing;
use crate::config::Config;
use crate::service::intake::Rules;
use crate::store::{self, writer::Writer};

/// A bound, ready-to-run rackd.
pub struct Application {
    listener: TcpListener,
    router: axum::Router,
    writer_task: JoinHandle<()>,
}

impl Application {
    /// Opens the database, applies migrations and binds the listen address.
    ///
    /// Without API keys, rackd refuses to listen on anything but loopback unless
    /// `insecure` is set: an open WCS on a plant network would let anyone move boxes.
    pub async fn build(config: &Config, insecure: bool) -> anyhow::Result<Application> {
        let keys = KeyRing::new(&config.auth.keys);
        let listen = config.server.listen;
        if keys.is_empty() {
            if !listen.ip().is_loopback() && !insecure {
                bail!(
                    "no [[auth.keys]] are configured, so rackd only serves loopback; refusing {listen} \
                     (add keys, or pass --insecure to serve without authentication)"
                );
            }
            tracing::warn!(%listen, "no API keys configured: every request is allowed");
        }
        let db = &config.database;
        let pool = store::open(&db.path, Duration::from_millis(db.busy_timeout_ms))
            .await
            .with_context(|| format!("opening database {}", db.path.display()))?;
        let (writer, writer_task) =
            Writer::start(pool.clone(), config.intake.max_group, config.intake.queue, None);
        let state = AppState {
            pool,
            writer,
            rules: Arc::new(Rules { layout: config.layout(), devices: Default::default() }),
            keys: Arc::new(keys),
            metrics: Arc::new(Metrics::default()),
        };
        let timeout = Duration::from_secs(config.server.request_timeout_secs);
        let router = api::router(state, config.server.body_limit_bytes, timeout);
        let listener = TcpListener::bind(listen).await.with_context(|| format!("binding {listen}"))?;
        Ok(Application { listener, router, writer_task })
    }

    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.listener.local_addr().expect("a bound listener has an address")
    }

    /// Serves until `shutdown` completes, then finishes in-flight requests and pending
    /// commits before returning.
    pub async fn run_until(self, shutdown: impl Future<Output = ()> + Send + 'static) -> anyhow::Result<()> {
        tracing::info!(addr = %self.local_addr(), "rackd listening");
        axum::serve(self.listener, self.router).with_graceful_shutdown(shutdown).await?;
        // The router (and with it the last writer handle) is gone: the writer drains and stops.
        self.writer_task.await.context("job writer")?;
        tracing::info!("rackd stopped");
        Ok(())
    }
}

/// Completes on SIGINT or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! { _ = ctrl_c => {}, _ = term => {} }
    tracing::info!("shutdown requested");
}
