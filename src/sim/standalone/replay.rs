//! `rackd sim replay`: a capture's device side served until Ctrl-C, or until the recording
//! has been played out for a while; then the report.
//!
//! "Played out" is [`ReplayServer::exhausted`]: every recorded write made and the clock
//! past the last request. rackd never falls silent (it polls on), so the end is that
//! state held for `idle`; the polls meanwhile get the recording's last answers.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;

use crate::capture::read_file;
use crate::sim::replay::{ReplayServer, Report, Script};

/// What to replay, where, and when to stop.
#[derive(Clone, Debug)]
pub struct ReplayOptions {
    /// The capture (pcapng).
    pub file: PathBuf,
    /// Where to serve; None: 127.0.0.1 on the recorded device's port.
    pub listen: Option<SocketAddr>,
    /// Writes this close in the recording may come either way round.
    pub reorder: Duration,
    /// How long the recording stays played out before the replay ends.
    pub idle: Duration,
}

/// Serves the capture until Ctrl-C or the end; prints and returns the report.
pub async fn run(options: ReplayOptions) -> anyhow::Result<Report> {
    let capture = read_file(&options.file).with_context(|| format!("{}", options.file.display()))?;
    let script = Script::new(&capture).with_context(|| format!("{}", options.file.display()))?;
    let listen = options.listen.unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], script.device.port())));
    let (requests, dialect, transport) = (script.requests.len(), script.dialect, script.transport);
    let server = ReplayServer::start(script, listen, options.reorder)
        .await
        .with_context(|| format!("cannot serve on {listen}"))?;
    println!(
        "replaying {requests} requests ({dialect:?} over {transport:?}) of {} on {}",
        options.file.display(),
        server.local_addr()
    );
    let mut played_out_since: Option<tokio::time::Instant> = None;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    loop {
        tokio::select! {
            _ = tokio::signal::ctrl_c() => break,
            _ = tick.tick() => {
                if !server.exhausted() {
                    played_out_since = None;
                } else if played_out_since.get_or_insert_with(tokio::time::Instant::now).elapsed() >= options.idle {
                    println!("the recording is played out");
                    break;
                }
            }
        }
    }
    let report = server.stop();
    println!("{report}");
    Ok(report)
}
