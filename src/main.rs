//! The `rackd` binary: parse the command line, start logging, hand over to the library.

#![forbid(unsafe_code)]

use std::io::IsTerminal;
use std::process::ExitCode;

use clap::Parser;
use rackd::cli::{Cli, LogFormat};
use tracing_subscriber::EnvFilter;

/// mimalloc instead of glibc's malloc: measured in `bench intake` (batches +8%, +12% with
/// the writer's statements allocated at their size), see docs/development/benchmarks/intake.md. The
/// benchmark (`examples/bench`) uses the same, so it measures this. It serves C's `malloc`
/// too (the crate's `override` feature, in Cargo.toml), so SQLite's allocations as well.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[tokio::main]
async fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter = EnvFilter::try_from_env("RACKD_LOG").unwrap_or_else(|_| EnvFilter::new("info"));
    // Colour only for a person at a terminal: files and container logs get plain text, and
    // NO_COLOR (https://no-color.org) turns it off everywhere.
    let ansi = std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
    let logs = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_ansi(ansi);
    match cli.log_format {
        LogFormat::Text => logs.init(),
        LogFormat::Json => logs.json().init(),
    }
    match rackd::cli::run(cli).await {
        Ok(code) => code,
        Err(e) => {
            eprintln!("rackd: {}", rackd::cli::describe(&e));
            ExitCode::FAILURE
        }
    }
}
