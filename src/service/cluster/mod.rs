//! Hot standby: several rackd nodes on one PostgreSQL, exactly one of them **active**
//! (driving the machines), the others **standby**. This module is the leadership: a lease
//! row in the shared database, renewed by the active node, with an epoch (a fencing token)
//! that grows at every takeover ([`lease`] for the rules on each side, [`run`] for the
//! loop, `store::cluster` for the statements).
//!
//! # The timing argument
//!
//! Two kinds of clock are involved, and neither needs to agree with another node's:
//! - The **active node** notes its own monotonic time `t0` *before* it sends a renewal. When
//!   the renewal commits, it may drive the machines until `t0 + lease`, and not one instant
//!   longer: it checks [`Gate::may_drive`] before every device write, and the loop gives
//!   up a renewal still in flight at that instant (a database that stops answering cannot
//!   hold it past its lease).
//! - A **standby** watches the lease row. It notes on *its own* monotonic clock the first
//!   instant `s` it saw the row as it now stands (`epoch`, `beat`), and takes over only if
//!   the row still stands so at `s + lease + margin`, by a compare-and-set on exactly that
//!   `(epoch, beat)`.
//!
//! Why no two nodes drive at once: the renewal that produced the row the standby saw was
//! sent at some `t0` before it committed, and it committed before the standby read it, so
//! `t0 <= s` in real time. The old node stopped at `t0 + lease`; the standby starts after
//! `s + lease + margin`, at least `margin` later. If the old node renewed in between, the
//! row changed and the compare-and-set fails. The only assumption is that the two nodes'
//! monotonic clocks run at rates that differ by less than `margin / lease` (20% with the
//! defaults; real oscillators differ by parts per million). No wall clock, no NTP, no
//! clock of the database server enters it.
//!
//! **A network partition** between the active node and the database is the same case:
//! its renewals stop committing, it stops driving at `t0 + lease` on its own, and a
//! standby that still reaches the database takes over `margin` later at the earliest. A
//! partition between a standby and the database only delays that standby.
//!
//! **What the lease cannot fence** is a device write already past the check when the
//! process froze (a VM paused, a swap storm) for longer than `margin`: machines take no
//! fencing token. The database side is fenced, though: every dispatch write of the active
//! node is committed under [`crate::store::cluster::fence`], which locks the lease row `FOR
//! KEY SHARE` while a takeover locks it `FOR UPDATE`, so a node that lost the lease cannot
//! commit a dispatch, and the new node's reconciliation (as after a restart) reads every
//! commit the old one made. The renewal's `UPDATE` does not conflict with that lock, so an
//! open write transaction never holds a renewal back past the lease (`store::cluster` has
//! the argument).

pub mod follow;
pub mod lease;
pub mod node;

use std::sync::{Arc, Mutex};

use sqlx::PgPool;
use tokio::sync::watch;
use tokio::time::{Instant, sleep, sleep_until, timeout_at};

use crate::store::cluster;
use lease::{Holding, Timing, Watch};

pub use crate::store::cluster::LEASE;
pub use node::Node;

/// What an operator should do about a `config_drift` alarm.
pub const DRIFT_ACTION: &str = "Make the nodes' [site] and [[devices]] the same (one file for all, or the \
same edits on each), then reload each node (POST /api/v1/config/reload or SIGHUP); a standby keeps its reloaded \
configuration for when it takes over.";

/// What an operator should do after a takeover (the `takeover` alarm's action).
pub const TAKEOVER_ACTION: &str = "Find out why the node that was active stopped (its log, its host, its \
     network to the database) and start it again: it comes back as a standby, and the alarm clears once a \
     standby is back.";

/// What a node is now.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// It serves the API and watches the lease.
    Standby,
    /// It drives the machines, under this epoch.
    Active {
        /// The fencing token of its term.
        epoch: i64,
    },
}

impl Role {
    /// The epoch it drives under, if active.
    pub fn epoch(self) -> Option<i64> {
        match self {
            Role::Active { epoch } => Some(epoch),
            Role::Standby => None,
        }
    }
}

/// Whether this node may drive the machines at this instant, for the code that writes to
/// them (checked synchronously, before each write).
#[derive(Clone, Debug, Default)]
pub struct Gate(Arc<Mutex<Option<Holding>>>);

impl Gate {
    /// The epoch to act under, if the lease is held and not run out.
    pub fn may_drive(&self) -> Option<i64> {
        let held = self.0.lock().unwrap_or_else(|p| p.into_inner());
        held.as_ref().filter(|h| h.valid(Instant::now())).map(|h| h.epoch)
    }

    /// The epoch a fenced writer handle acts under ([`crate::store::writer::Writer::fenced`]).
    pub fn epoch(&self) -> crate::store::writer::Epoch {
        let gate = self.clone();
        Arc::new(move || gate.may_drive())
    }

    /// The check a machine link makes before each request ([`crate::devices::gate`]).
    pub fn may(&self) -> crate::devices::gate::MayDrive {
        let gate = self.clone();
        Arc::new(move || gate.may_drive().is_some())
    }

    fn set(&self, holding: Option<Holding>) {
        *self.0.lock().unwrap_or_else(|p| p.into_inner()) = holding;
    }
}

/// A node's leadership: its gate, and its role as it changes.
pub struct Leadership {
    /// Checked before every device write.
    pub gate: Gate,
    /// The role, changed as the loop decides.
    pub role: watch::Receiver<Role>,
    task: tokio::task::JoinHandle<()>,
}

impl Leadership {
    /// Starts `node`'s leadership loop on `pool`.
    pub fn start(pool: PgPool, node: String, timing: Timing) -> Leadership {
        let gate = Gate::default();
        let (tx, role) = watch::channel(Role::Standby);
        let task = tokio::spawn(run(pool, node, timing, gate.clone(), tx));
        Leadership { gate, role, task }
    }

    /// Stops the loop; the lease, if held, runs out on its own (as when the process dies).
    pub fn abort(&self) {
        self.task.abort();
        self.gate.set(None);
    }

    /// Stops the loop and lets go of the lease, so a standby takes over at once.
    pub async fn release(self, pool: &PgPool, node: &str) -> Result<(), sqlx::Error> {
        self.task.abort();
        let held = self.gate.0.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(h) = held {
            cluster::release(pool, LEASE, node, h.epoch).await?;
        }
        Ok(())
    }
}

/// The leadership loop: watch as a standby, take the lease when it stands still, renew it
/// while active, and fall back to standby the moment it runs out.
pub async fn run(pool: PgPool, node: String, timing: Timing, gate: Gate, role: watch::Sender<Role>) {
    let mut watch = Watch::default();
    loop {
        let Some(mut holding) = stand_by(&pool, &node, timing, &mut watch).await else { continue };
        gate.set(Some(holding.clone()));
        role.send_replace(Role::Active { epoch: holding.epoch });
        tracing::info!(node, epoch = holding.epoch, "cluster: this node is active");
        loop {
            let sent = Instant::now();
            match timeout_at(holding.until(), cluster::renew(&pool, LEASE, &node, holding.epoch)).await {
                Ok(Ok(true)) => {
                    holding.renewed(sent, timing);
                    gate.set(Some(holding.clone()));
                }
                Ok(Ok(false)) => break,
                Ok(Err(e)) => tracing::warn!(error = %e, "cluster: the lease could not be renewed"),
                Err(_) => {}
            }
            sleep_until((sent + timing.renew_every()).min(holding.until())).await;
            if !holding.valid(Instant::now()) {
                break;
            }
        }
        gate.set(None);
        role.send_replace(Role::Standby);
        tracing::error!(
            node,
            epoch = holding.epoch,
            "cluster: the lease is lost; this node stops driving the machines"
        );
        watch = Watch::default();
    }
}

/// One standby round: read the lease, and take it if it may be taken. Some when taken.
async fn stand_by(pool: &PgPool, node: &str, timing: Timing, watch: &mut Watch) -> Option<Holding> {
    match cluster::read(pool, LEASE).await {
        Ok(row) => watch.observe(row, Instant::now()),
        Err(e) => {
            tracing::warn!(error = %e, "cluster: the lease cannot be read");
            sleep(timing.poll_every()).await;
            return None;
        }
    }
    if watch.may_take(Instant::now(), timing) {
        let sent = Instant::now();
        match cluster::take(pool, LEASE, node, watch.seen()).await {
            Ok(Some(epoch)) => return Some(Holding::new(epoch, sent, timing)),
            Ok(None) => {}
            Err(e) => tracing::warn!(error = %e, "cluster: the lease could not be taken"),
        }
    }
    sleep(timing.poll_every()).await;
    None
}
