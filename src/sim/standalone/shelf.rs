//! `rackd sim shelf`: the shelf storage PLC alone ([`crate::sim::shelf`]).

use anyhow::Context;

use crate::sim::shelf::{ShelfSim, ShelfSimOptions};

/// Runs the shelf simulator on `listen` (an address, or a serial device) until Ctrl-C.
pub async fn run(listen: &str, options: ShelfSimOptions) -> anyhow::Result<()> {
    let (protocol, slots) = (options.protocol, options.slots);
    let sim = ShelfSim::start(listen, options)
        .await
        .with_context(|| format!("starting the {protocol} shelf simulator on {listen}"))?;
    let at = sim.local_addr().map_or_else(|| listen.to_owned(), |a| a.to_string());
    println!(
        "shelf PLC simulator ({}) on {at}: {} slots from {}, {} words apart, unit {}",
        sim.protocol(),
        slots,
        sim.base(),
        sim.stride(),
        sim.unit()
    );
    tokio::signal::ctrl_c().await?;
    let (done, failed) = sim.finished();
    println!("tasks finished {done}, failed {failed}; busy-slot violations {}", sim.violations());
    sim.shutdown().await;
    Ok(())
}
