//! rackd served in the benchmark's own process, on the configuration's address, until told
//! to stop: what `intake`, `shelf` and `crane` measure against.

use rackd::app::Application;
use rackd::config::Config;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// A running rackd.
pub struct Served {
    /// `http://ADDR`, or `https://ADDR` with `[server.tls]`.
    pub base: String,
    stop: oneshot::Sender<()>,
    server: JoinHandle<anyhow::Result<()>>,
}

impl Served {
    /// Builds rackd from `config` and serves it.
    pub async fn start(config: &Config) -> anyhow::Result<Served> {
        let app = Application::build(config, false).await?;
        let scheme = if config.server.tls.is_some() { "https" } else { "http" };
        let base = format!("{scheme}://{}", app.local_addr());
        let (stop, stopped) = oneshot::channel::<()>();
        let server = tokio::spawn(app.run_until(async {
            let _ = stopped.await;
        }));
        Ok(Served { base, stop, server })
    }

    /// Stops it and waits until it has.
    pub async fn stop(self) -> anyhow::Result<()> {
        let _ = self.stop.send(());
        self.server.await?
    }
}
