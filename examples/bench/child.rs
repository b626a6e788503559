//! rackd as a child process, so that its CPU time can be read apart from the load
//! generator's (the process's CPU-time clock, to the nanosecond).

use std::ffi::OsString;
use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Parser;
use rackd::cli::{Cli, LogFormat};
use tracing_subscriber::EnvFilter;

/// The first argument that makes this executable run rackd's command line instead of a
/// benchmark.
pub const RACKD: &str = "rackd";

/// Runs rackd's command line with `args` (`args[0]` is the program name), as the `rackd`
/// binary does: the same logging set-up, the same library entry point.
pub fn run_rackd(args: &[OsString]) -> ExitCode {
    let cli = Cli::parse_from(args);
    let filter = EnvFilter::try_from_env("RACKD_LOG").unwrap_or_else(|_| EnvFilter::new("info"));
    let logs = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
    match cli.log_format {
        LogFormat::Text => logs.init(),
        LogFormat::Json => logs.json().init(),
    }
    let runtime = tokio::runtime::Runtime::new().expect("a tokio runtime");
    match runtime.block_on(rackd::cli::run(cli)) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("rackd: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// A `rackd serve` running as a child process; killed when dropped.
pub struct Server {
    process: tokio::process::Child,
    /// Its process id.
    pub pid: u32,
    /// `127.0.0.1:PORT`, where it serves HTTP.
    pub addr: String,
}

impl Server {
    /// Starts `rackd serve` with `config` and a database in `dir`, and waits until it is ready.
    pub async fn start(config: &Path, dir: &Path) -> anyhow::Result<Server> {
        let port = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
        let addr = format!("127.0.0.1:{port}");
        let process = tokio::process::Command::new(std::env::current_exe()?)
            .args([RACKD, "serve", "--config"])
            .arg(config)
            .args(["--listen", &addr, "--database"])
            .arg(dir.join("bench.db"))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .kill_on_drop(true)
            .spawn()
            .context("starting rackd serve")?;
        let pid = process.id().context("the server's pid")?;
        let server = Server { process, pid, addr };
        server.wait_ready().await?;
        Ok(server)
    }

    async fn wait_ready(&self) -> anyhow::Result<()> {
        let client = reqwest::Client::new();
        let url = format!("http://{}/readyz", self.addr);
        for _ in 0..200 {
            if client.get(&url).send().await.is_ok_and(|r| r.status().is_success()) {
                return Ok(());
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        bail!("the server did not become ready")
    }

    /// CPU seconds the server has used so far.
    pub fn cpu_secs(&self) -> anyhow::Result<f64> {
        cpu_secs(self.pid)
    }

    /// Stops the server.
    pub async fn stop(mut self) {
        self.process.kill().await.ok();
    }
}

/// CPU seconds a process has used (user + system, every thread, ended ones included), from
/// its CPU-time clock (`clock_getcpuclockid`): to the nanosecond, where `/proc/PID/stat`
/// counts in ticks of 10 ms, 3% of what rackd uses in a 10 s round of `bench fleet`.
pub fn cpu_secs(pid: u32) -> anyhow::Result<f64> {
    let pid = i32::try_from(pid).context("a process id")?;
    let clock = nix::time::ClockId::pid_cpu_clock_id(nix::unistd::Pid::from_raw(pid))
        .with_context(|| format!("the CPU clock of process {pid}"))?;
    let t = clock.now().with_context(|| format!("the CPU time of process {pid}"))?;
    Ok(t.tv_sec() as f64 + t.tv_nsec() as f64 / 1e9)
}
