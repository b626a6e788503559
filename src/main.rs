//! The `rackd` command: parse the command line, start tracing, call into the library.

use clap::{Parser, Subcommand};
use rackd::cli;

#[derive(Parser)]
#[command(name = "rackd", version, about = "Warehouse control system")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Read or write a PLC's memory by hand.
    Plc(cli::plc::PlcArgs),
    /// Run a device simulator.
    #[command(subcommand)]
    Sim(SimCommand),
}

#[derive(Subcommand)]
enum SimCommand {
    /// A Modbus server with a full register bank.
    Modbus(cli::sim_modbus::SimModbusArgs),
}

#[tokio::main]
async fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let result = match Cli::parse().command {
        Command::Plc(args) => cli::plc::run(args).await,
        Command::Sim(SimCommand::Modbus(args)) => cli::sim_modbus::run(args).await,
    };
    if let Err(e) = result {
        eprintln!("rackd: {e:#}");
        std::process::exit(1);
    }
}
