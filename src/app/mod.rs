//! Building and running the service: open the store, start the devices, bind, serve, and
//! shut down gracefully. What drives the machines is [`drive`]; a cluster node's wiring is
//! [`cluster`]; how connections are accepted and served (timers, the cap, TLS) is
//! [`serve`].

mod cluster;
mod drive;
mod hooks;
mod serve;

use std::future::Future;
use std::net::SocketAddr;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use anyhow::{Context, bail};
use tokio::net::{TcpListener, TcpSocket};
use tokio::task::JoinHandle;

use crate::api::metrics::Metrics;
use crate::api::state::Shared;
use crate::api::{self, AppState};
use crate::auth::KeyRing;
use crate::config::{Config, Sources};
use crate::domain::time::now_ms;
use crate::service::dispatch::{Dispatcher, Queues, Setup};
use crate::service::events::Hub;
use crate::service::intake::Rules;
use crate::service::reload::Reload;
use crate::store::writer::Writer;
use crate::store::{self, locations};

/// How long a node that lost its cluster lease waits for its writer to drain.
const LOST_DRAIN: Duration = Duration::from_secs(5);

/// A bound, ready-to-run rackd.
pub struct Application {
    listener: TcpListener,
    router: axum::Router,
    /// `[server]`'s timers and cap.
    limits: serve::Limits,
    /// The certificate, when `[server.tls]` is set.
    tls: Option<serve::tls::Certificates>,
    writer_task: JoinHandle<()>,
    /// Device tasks, the device monitor, retention and the certificate's alarms: stopped
    /// before the writer drains.
    tasks: drive::Tasks,
    /// This node's part in a cluster.
    cluster: Option<cluster::Clustered>,
    /// The running configuration, and where to read it again.
    reload: Reload,
    /// The task that reloads on SIGHUP, if one listens.
    hangups: Option<JoinHandle<()>>,
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
        let keys = KeyRing::new(&config.auth);
        let listen = config.server.listen;
        // Before anything starts: a certificate that does not load is a start that fails.
        let tls = match &config.server.tls {
            Some(tls) => Some(serve::tls::Certificates::load(tls).context("server.tls")?),
            None => None,
        };
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
        // The loader has read url_file into url; a configuration built in code may not have.
        let url = match (&db.url, &db.url_file) {
            (Some(url), _) => Some(url.clone()),
            (None, Some(file)) => Some(crate::config::read_url_file(file).context("database.url_file")?),
            (None, None) => None,
        };
        let database = match url {
            Some(url) => store::Database::Postgres(url),
            None => store::Database::Sqlite(db.path.clone()),
        };
        let postgres = database.engine() == store::Engine::Postgres;
        let ca = db.ca_file.as_deref().filter(|_| postgres);
        let settings = store::Settings { ca, vfs: db.sqlite_vfs.as_deref().filter(|_| !postgres) };
        let with_ca = ca.map(|p| format!(" with database.ca_file {}", p.display())).unwrap_or_default();
        let known = store::schema::Known::new(database.engine().migrator());
        let known = match db.known_schema {
            Some(version) => known.up_to(version),
            None => known,
        };
        let (pool, schema) =
            store::open_known(&database, Duration::from_millis(db.busy_timeout_ms), settings, &known)
                .await
                .with_context(|| format!("opening database {}{with_ca}", database.display()))?;
        // The archive's folder takes files, or the start fails (`[retention]`); after the
        // database, whose own problems (its folder, say) say more when both are wrong.
        store::archive::check_folder(&config.retention.folder(&config.database.path))
            .context("retention.archive_dir")?;
        let layout = config.layout();
        locations::seed(&pool, &layout, now_ms()).await.context("seeding locations")?;
        let on_cluster = match (&config.cluster, &pool) {
            (Some(c), store::Pool::Postgres(pg)) => Some((c, pg.clone())),
            (Some(_), store::Pool::Sqlite(_)) => bail!("[cluster] needs a PostgreSQL database.url"),
            (None, _) => None,
        };
        let commits = Arc::new(AtomicU64::new(0));
        let rules = Rules::of(config);
        let queues = Queues::new(config.devices.iter().map(|d| Setup::of(d, &rules.deep, &pool, &commits)));
        let (_, last_event) = store::events::bounds(&pool).await.context("reading the event log")?;
        let hub = Hub::new(config.events.buffer, last_event);
        let metrics = Arc::new(Metrics::default());
        // Before the writer starts: from here on its commits change them.
        metrics.set_counts(store::counts::load(&pool).await.context("reading the counts of jobs")?);
        queues.set_drives(on_cluster.is_none());
        let store_fault = store::fault::StoreFault::default();
        let hooks = hooks::hooks(&queues, &hub, &metrics, &commits, &store_fault, on_cluster.is_some());
        let (max_group, queue) = (config.intake.max_group, config.intake.queue);
        let started = match on_cluster {
            Some(_) => Writer::start_shared(&pool, max_group, queue, hooks).await,
            None => Writer::start(&pool, max_group, queue, hooks).await,
        };
        let (writer, writer_task) = started.context("opening the job writer's connection")?;
        let leading = on_cluster.map(|(c, pg)| (c, cluster::lead(&pg, c), pg));
        // What the dispatcher writes is the active node's to write: fenced in a cluster.
        let dispatching = match &leading {
            Some((_, (leadership, _), _)) => writer.fenced(leadership.gate.epoch()),
            None => writer.clone(),
        };
        let dispatcher = Dispatcher::new(queues.clone(), dispatching, pool.clone());
        let parts = crate::service::reload::Parts {
            pool: pool.clone(),
            dispatcher: dispatcher.clone(),
            writer: writer.clone(),
            commits: commits.clone(),
        };
        let reload = Reload::new(config.clone(), parts);
        let webhooks = Arc::new(OnceLock::new());
        let tasks = drive::Tasks::default();
        // The served certificate's alarms and figures, on every node (each serves its own).
        if let (Some(tls), Some(files)) = (&tls, &config.server.tls) {
            let device = serve::certificate::device(config.cluster.as_ref().map(|c| c.node.as_str()));
            let watch = serve::certificate::watch(
                tls.served(),
                files.cert_file.clone(),
                device,
                writer.clone(),
                metrics.clone(),
            );
            tasks.lock().unwrap_or_else(|p| p.into_inner()).push(tokio::spawn(watch));
        }
        // The store's own alarm, on every node (each has its own writer).
        let watch = crate::service::store_alarm::watch(
            store_fault.clone(),
            writer.clone(),
            crate::service::store_alarm::device(config.cluster.as_ref().map(|c| c.node.as_str())),
        );
        tasks.lock().unwrap_or_else(|p| p.into_inner()).push(tokio::spawn(watch));
        let clustered = match leading {
            Some((c, (leadership, timing), pg)) => {
                let parts = cluster::Parts {
                    config: config.clone(),
                    listen: listener.local_addr().context("the bound address")?,
                    pool: pool.clone(),
                    pg,
                    schema: schema.known,
                    dispatcher: dispatcher.clone(),
                    writer: writer.clone(),
                    hub: hub.clone(),
                    metrics: metrics.clone(),
                    commits: commits.clone(),
                    reload: reload.clone(),
                    webhooks: webhooks.clone(),
                    tasks: tasks.clone(),
                };
                Some(cluster::start(c, leadership, timing, parts).await?)
            }
            None => {
                let d = drive::start(config, &pool, &dispatcher, writer.clone(), &hub, None).await?;
                reload.drive(d.fleet);
                let _ = webhooks.set(d.webhooks);
                tasks.lock().unwrap_or_else(|p| p.into_inner()).extend(d.tasks);
                None
            }
        };
        let forwarder = match &config.cluster {
            Some(c) => {
                let listen = listener.local_addr().context("the bound address")?;
                api::peer::warn_if_clear(
                    &c.url(listen, config.server.tls.is_some()),
                    !keys.is_empty(),
                    "this node's cluster.url",
                );
                let forwarder = api::peer::Forwarder::new(
                    c.ca_file.as_deref(),
                    config.server.body_limit_bytes,
                    !keys.is_empty(),
                );
                Some(forwarder.context("the cluster's forwarding client (cluster.ca_file)")?)
            }
            None => None,
        };
        let state = AppState::new(Shared {
            reload: reload.clone(),
            pool,
            writer,
            metrics,
            webhooks,
            subscriptions: Arc::new(config.webhooks.clone()),
            cluster: clustered.as_ref().map(|c| c.node.clone()),
            forwarder,
            dispatcher,
            hub,
            events: Arc::new(config.events.clone()),
            hosts: api::keyless::Hosts::new(
                listener.local_addr().context("the bound address")?,
                &config.server.allowed_hosts,
            ),
            captures: config.retention.captures(&config.database.path),
            capture_builds: Arc::new(tokio::sync::Semaphore::new(config.server.capture_downloads)),
            failures: api::failures::Failures::default(),
            store_fault,
        });
        let timeout = Duration::from_secs(config.server.request_timeout_secs);
        let router = api::router(state, config.server.body_limit_bytes, timeout);
        Ok(Application {
            listener,
            router,
            limits: serve::Limits::of(&config.server),
            tls,
            writer_task,
            tasks,
            cluster: clustered,
            reload,
            hangups: None,
            keep: Vec::new(),
        })
    }

    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.listener.local_addr().expect("a bound listener has an address")
    }

    /// Reloads (`POST /api/v1/config/reload`) read `sources` again: those the running
    /// configuration was loaded from. Without them, a reload is refused.
    pub fn reload_from(&self, sources: Sources) {
        self.reload.read_from(sources);
    }

    /// The running configuration and where to read it again.
    pub fn reload(&self) -> Reload {
        self.reload.clone()
    }

    /// Reloads on each SIGHUP from now on, as `POST /api/v1/config/reload` does
    /// ([`crate::service::reload::on_hangups`]), until the service stops.
    #[cfg(unix)]
    pub fn reload_on(&mut self, hangups: tokio::signal::unix::Signal) {
        self.hangups = Some(tokio::spawn(crate::service::reload::on_hangups(self.reload.clone(), hangups)));
    }

    /// Keeps `thing` (an in-process simulator, say) alive as long as the service runs.
    pub fn keep(&mut self, thing: impl std::any::Any + Send) {
        self.keep.push(Box::new(thing));
    }

    /// Serves until `shutdown` completes, then finishes in-flight requests, stops the
    /// devices between two steps and commits what is pending before returning.
    pub async fn run_until(self, shutdown: impl Future<Output = ()> + Send + 'static) -> anyhow::Result<()> {
        let scheme = if self.tls.is_some() { "https" } else { "http" };
        tracing::info!(addr = %self.local_addr(), scheme, "rackd listening");
        let lost = self.cluster.as_ref().map(|c| c.lost.clone());
        let stop = async move {
            match lost {
                Some(mut lost) => tokio::select! {
                    _ = shutdown => {}
                    _ = lost.wait_for(Option::is_some) => {}
                },
                None => shutdown.await,
            }
        };
        // Each request carries its peer's address (`ConnectInfo`, set by `serve`): the audit
        // log names it, and failed authentications are counted by it (`api::failures`).
        serve::serve(self.listener, self.router, self.limits, self.tls, stop).await;
        // A device stopped between two PLC requests is the same as a crash, which the
        // hand-over order and recovery make safe.
        if let Some(hangups) = self.hangups {
            hangups.abort();
            let _ = hangups.await;
        }
        let tasks = std::mem::take(&mut *self.tasks.lock().unwrap_or_else(|p| p.into_inner()));
        drive::stop(tasks).await;
        if let Some(fleet) = self.reload.fleet() {
            fleet.abort().await;
        }
        // The last handles to the writer (the reload's, the devices') go with it.
        drop(self.reload);
        let mut failure = None;
        if let Some(c) = self.cluster {
            failure = c.lost.borrow().clone();
            for task in &c.background {
                task.abort();
            }
            // Stopped cleanly: let go of the lease, so a standby takes over at once.
            if failure.is_none() {
                let pool = c.node.pool.clone();
                if let Err(e) = c.leadership.release(&pool, &c.node.name).await {
                    tracing::warn!(error = %e, "cluster: the lease could not be let go; it runs out instead");
                }
            } else {
                c.leadership.abort();
            }
        }
        // The router and devices (and with them the last writer handles) are gone: the
        // writer drains and stops. A node that lost its lease may have lost its database
        // too (a partition): it waits a little for the writer, not for a TCP timeout.
        if let Some(why) = failure {
            if tokio::time::timeout(LOST_DRAIN, self.writer_task).await.is_err() {
                tracing::warn!("the job writer did not drain in {LOST_DRAIN:?}; stopping without it");
            }
            drop(self.keep);
            bail!("{why}; start it again to stand by");
        }
        self.writer_task.await.context("job writer")?;
        drop(self.keep);
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

/// Connections the kernel completes and queues for rackd to accept. The standard
/// library's 128 overflows under a burst (a flood of connections, many clients starting at
/// once), and the kernel then drops new connections' SYNs, which their clients send again
/// only a second later: `/healthz` among them. The kernel caps it at `net.core.somaxconn`
/// (4096 on current kernels).
const BACKLOG: u32 = 1024;

/// Binds the API's listener.
pub async fn bind(listen: SocketAddr) -> anyhow::Result<TcpListener> {
    let bound = || {
        let socket = if listen.is_ipv4() { TcpSocket::new_v4()? } else { TcpSocket::new_v6()? };
        // As the standard library's bind: a restart does not wait for TIME_WAIT to pass.
        socket.set_reuseaddr(true)?;
        socket.bind(listen)?;
        socket.listen(BACKLOG)
    };
    bound().with_context(|| format!("binding {listen} (is another rackd running?)"))
}
