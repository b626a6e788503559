//! This node in its cluster, as the API and `/metrics` see it: its name, where its API is
//! reached, its role as the leadership loop changes it, and how often it took over.
//! [`tell`] keeps the node's row in `cluster_nodes` fresh, for `GET /api/v1/cluster` and
//! for a standby looking for the active node's API; the row carries the hash of the
//! configuration the node runs ([`Node::drift`]: which nodes run another one), and the
//! node's version and schema (a site upgrading one node at a time sees both releases).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use sqlx::PgPool;
use tokio::sync::watch;
use tokio::time::sleep;

use super::lease::Timing;
use super::{Gate, Role};
use crate::store::cluster::{self, LEASE, LeaseRow, NodeRow};

/// This node, for the API.
#[derive(Clone)]
pub struct Node {
    /// Its name (`[cluster] node`).
    pub name: String,
    /// Where the other nodes reach its API.
    pub url: String,
    /// Its role, as the leadership loop decides.
    pub role: watch::Receiver<Role>,
    /// Whether it may drive the machines at this instant.
    pub gate: Gate,
    /// The shared database.
    pub pool: PgPool,
    /// The lease timing.
    pub timing: Timing,
    /// How many times this process became the active node.
    pub takeovers: Arc<AtomicU64>,
    /// When this process started, ms since 1970.
    pub started_at: i64,
    /// The configuration it runs (its hash told with its row; a reload changes it).
    pub config: watch::Receiver<crate::config::RunningConfig>,
    /// The schema it knows: the newest migration compiled in (`store::schema`), told with
    /// its row beside the binary's version ([`VERSION`]).
    pub schema: i64,
}

/// This binary's version, as the nodes tell it.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The cluster as one node sees it.
#[derive(Clone, Debug)]
pub struct View {
    /// The lease row, if anyone ever held it.
    pub lease: Option<LeaseRow>,
    /// Every node that ever told of itself.
    pub nodes: Vec<NodeRow>,
    /// The database server's clock, ms since 1970 (ages are measured on it).
    pub now: i64,
    /// The newest migration applied in the database.
    pub schema: i64,
}

impl Node {
    /// The role now.
    pub fn role(&self) -> Role {
        *self.role.borrow()
    }

    /// `active` or `standby`.
    pub fn role_name(&self) -> &'static str {
        match self.role() {
            Role::Active { .. } => "active",
            Role::Standby => "standby",
        }
    }

    /// Times this process took over.
    pub fn takeovers(&self) -> u64 {
        self.takeovers.load(Ordering::Relaxed)
    }

    /// The lease and the nodes, as stored.
    pub async fn view(&self) -> Result<View, sqlx::Error> {
        let lease = cluster::read(&self.pool, LEASE).await?;
        let (nodes, now) = cluster::nodes(&self.pool).await?;
        let schema =
            crate::store::schema::database_schema(&crate::store::Pool::Postgres(self.pool.clone())).await?;
        Ok(View { lease, nodes, now, schema })
    }

    /// The nodes seen within two leases whose configuration differs from this node's, as
    /// (name, hash); nodes that told no hash are left out.
    pub fn drift(&self, view: &View) -> Vec<(String, String)> {
        let own = self.config.borrow().hash.clone();
        let fresh = (self.timing.lease * 2).as_millis() as i64;
        view.nodes
            .iter()
            .filter(|n| n.name != self.name && view.now - n.seen_at < fresh)
            .filter(|n| !n.config_hash.is_empty() && n.config_hash != own)
            .map(|n| (n.name.clone(), n.config_hash.clone()))
            .collect()
    }

    /// The node that holds the lease, if it is another one and tells where its API is.
    pub async fn active(&self) -> Result<Option<NodeRow>, sqlx::Error> {
        let view = self.view().await?;
        let Some(lease) = view.lease.filter(|l| !l.released && l.holder != self.name) else {
            return Ok(None);
        };
        Ok(view.nodes.into_iter().find(|n| n.name == lease.holder))
    }
}

/// Keeps `node`'s row fresh: at start, at every change of role, and three times a lease.
pub async fn tell(node: Node) {
    let mut role = node.role.clone();
    loop {
        let said = node.role_name();
        let hash = node.config.borrow().hash.clone();
        let told =
            cluster::Told { url: &node.url, role: said, started_at: node.started_at, config_hash: &hash };
        let version = (VERSION, node.schema);
        if let Err(e) = cluster::tell(&node.pool, &node.name, &told, version).await {
            tracing::warn!(error = %e, "cluster: cannot tell the other nodes of this one");
        }
        tokio::select! {
            changed = role.changed() => if changed.is_err() { return },
            _ = sleep(node.timing.renew_every()) => {}
        }
    }
}
