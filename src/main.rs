//! The `rackd` binary: parse the command line, start logging, hand over to the library.

use std::process::ExitCode;

use clap::Parser;
use rackd::cli::{Cli, LogFormat};
use tracing_subscriber::EnvFilter;

#[tokio::main]
async fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter = EnvFilter::try_from_env("RACKD_LOG").unwrap_or_else(|_| EnvFilter::new("info"));
    let logs = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr);
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
