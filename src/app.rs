//! Building and running the service: open the store, start the devices, bind, serve, and
//! shut down gracefully.

use std::collections::BTreeSet;
use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;

use crate::api::metrics::Metrics;
use crate::api::state::Shared;
use crate::api::{self, AppState};
use crate::auth::KeyRing;
use crate::config::Config;
use crate::devices::config::DeviceConfig;
use crate::devices::{self, Devices};
use crate::domain::time::now_ms;
use crate::service::dispatch::{Dispatcher, Queues, Setup};
use crate::service::events::Hub;
use crate::service::intake::Rules;
use crate::service::monitor;
use crate::service::planner::CranePlanner;
use crate::store::writer::{Hooks, Record, Writer};
use crate::store::{self, locations};

/// A bound, ready-to-run rackd.
pub struct Application {
    listener: TcpListener,
    router: axum::Router,
    writer_task: JoinHandle<()>,
    /// Device tasks, the device monitor and retention: stopped before the writer drains.
    device_tasks: Vec<JoinHandle<()>>,
    devices: Devices,
    keep: Vec<Box<dyn std::any::Any + Send>>,
}

impl Application {
    /// Opens the database, applies migrations, starts the devices and binds the listen
    /// address.
    ///
    /// Without API keys, rackd refuses to listen on anything but loopback unless
    /// `insecure` is set: an open WCS on a plant network would let anyone move boxes.
    pub async fn build(config: &Config, insecure: bool) -> anyhow::Result<Application> {
        let listener = bind(config.server.listen).await?;
        Application::build_on(config, listener, insecure).await
    }

    /// As [`Application::build`], serving on `listener` (bound by the caller before it
    /// starts anything else, so a port in use is the first thing reported).
    pub async fn build_on(
        config: &Config,
        listener: TcpListener,
        insecure: bool,
    ) -> anyhow::Result<Application> {
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
        let database = match &db.url {
            Some(url) => store::Database::Postgres(url.clone()),
            None => store::Database::Sqlite(db.path.clone()),
        };
        let pool = store::open(&database, Duration::from_millis(db.busy_timeout_ms))
            .await
            .with_context(|| format!("opening database {}", database.display()))?;
        let layout = config.layout();
        locations::seed(&pool, &layout, now_ms()).await.context("seeding locations")?;
        let commits = Arc::new(AtomicU64::new(0));
        let deep: BTreeSet<u16> =
            config.site.aisles.iter().filter(|a| a.depth == 2).map(|a| a.aisle).collect();
        let queues = Queues::new(config.devices.iter().map(|d| Setup {
            id: d.id().to_owned(),
            window: d.dispatch_window(),
            aisles: d.aisles().to_vec(),
            planner: match d {
                DeviceConfig::Crane(c) => {
                    Some(Arc::new(CranePlanner::new(c, &deep, pool.clone(), commits.clone())))
                }
                _ => None,
            },
        }));
        let hub = Hub::new(config.events.buffer);
        let metrics = Arc::new(Metrics::default());
        let hooks = Hooks {
            locked: Some(queues.locked_hook()),
            committed: Some(queues.hook()),
            publish: Some({
                let (publish, commits) = (hub.hook(), commits.clone());
                Arc::new(move |events| {
                    commits.fetch_add(1, Ordering::Release);
                    publish(events)
                })
            }),
            observe: Some(metrics.writer_hook()),
            tell: Some(queues.tell_hook()),
        };
        let (writer, writer_task) = Writer::start(&pool, config.intake.max_group, config.intake.queue, hooks)
            .await
            .context("opening the job writer's connection")?;
        let dispatcher = Dispatcher::new(queues.clone(), writer.clone(), pool.clone());
        dispatcher.load(config.devices.iter().map(|d| d.id())).await.context("loading the queues")?;
        dispatcher.restore().await.context("restoring pauses and location locks")?;
        let contact_refresh = Duration::from_millis(config.events.contact_refresh_ms);
        let port = |id: &str| queues.port(id, writer.clone());
        let (devices, mut device_tasks) = devices::start(&config.devices, port, contact_refresh).await?;
        device_tasks.extend(monitor::start(&devices, &queues, writer.clone(), &pool).await);
        queues.watch_devices(devices.iter().map(|(id, h)| (id.clone(), h.status.clone())).collect());
        device_tasks
            .push(tokio::spawn(crate::service::dispatch::waiting::watch(queues.clone(), writer.clone())));
        device_tasks.push(tokio::spawn(retention(writer.clone(), config.events.retention_hours)));
        let crane_aisles = config
            .devices
            .iter()
            .filter(|d| matches!(d, DeviceConfig::Crane(_)))
            .flat_map(|d| d.aisles().iter().copied())
            .collect();
        let rules = Rules {
            layout,
            deep,
            crane_aisles,
            devices: config.devices.iter().map(|d| (d.id().to_owned(), d.kind().job_kinds())).collect(),
            routes: config
                .devices
                .iter()
                .flat_map(|d| d.aisles().iter().map(|&a| (a, d.id().to_owned())))
                .collect(),
        };
        let state = AppState::new(Shared {
            pool,
            writer,
            rules: Arc::new(rules),
            keys: Arc::new(keys),
            metrics,
            devices: devices.clone(),
            dispatcher,
            hub,
            events: Arc::new(config.events.clone()),
        });
        let timeout = Duration::from_secs(config.server.request_timeout_secs);
        let router = api::router(state, config.server.body_limit_bytes, timeout);
        Ok(Application { listener, router, writer_task, device_tasks, devices, keep: Vec::new() })
    }

    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.listener.local_addr().expect("a bound listener has an address")
    }

    /// The running devices.
    pub fn devices(&self) -> &Devices {
        &self.devices
    }

    /// Keeps `thing` (an in-process simulator, say) alive as long as the service runs.
    pub fn keep(&mut self, thing: impl std::any::Any + Send) {
        self.keep.push(Box::new(thing));
    }

    /// Serves until `shutdown` completes, then finishes in-flight requests, stops the
    /// devices between two steps and commits what is pending before returning.
    pub async fn run_until(self, shutdown: impl Future<Output = ()> + Send + 'static) -> anyhow::Result<()> {
        tracing::info!(addr = %self.local_addr(), "rackd listening");
        // No Nagle: live events and replies are small writes that must leave at once
        // (Nagle's wait for an ACK, against a delayed ACK, stalls them by up to 40 ms).
        let listener = axum::serve::ListenerExt::tap_io(self.listener, |tcp| {
            if let Err(e) = tcp.set_nodelay(true) {
                tracing::debug!(error = %e, "TCP_NODELAY");
            }
        });
        axum::serve(listener, self.router).with_graceful_shutdown(shutdown).await?;
        // A device stopped between two PLC requests is the same as a crash, which the
        // hand-over order and recovery make safe.
        for task in &self.device_tasks {
            task.abort();
        }
        for task in self.device_tasks {
            let _ = task.await;
        }
        drop(self.devices);
        // The router and devices (and with them the last writer handles) are gone: the
        // writer drains and stops.
        self.writer_task.await.context("job writer")?;
        drop(self.keep);
        tracing::info!("rackd stopped");
        Ok(())
    }
}

/// Deletes events older than the retention from the log, at start and then every tenth of
/// the retention (at most hourly).
async fn retention(writer: Writer, hours: u64) {
    let keep = Duration::from_secs(hours.saturating_mul(3600));
    let mut tick = tokio::time::interval((keep / 10).min(Duration::from_secs(3600)));
    loop {
        tick.tick().await;
        let before_ms = now_ms().saturating_sub(keep.as_millis() as i64);
        match writer.record(Record::Prune { before_ms }).await {
            Ok(()) => {}
            Err(store::writer::WriteError::Closed) => return,
            Err(e) => tracing::warn!(error = %e, "pruning the event log"),
        }
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

/// Binds the API's listener.
pub async fn bind(listen: SocketAddr) -> anyhow::Result<TcpListener> {
    TcpListener::bind(listen).await.with_context(|| format!("binding {listen} (is another rackd running?)"))
}
