//! The cluster lease's statements (PostgreSQL only; see `service::cluster` for what they
//! mean together and the timing argument).
//!
//! Each statement is one compare-and-set on the lease row, so two nodes racing for it
//! cannot both win: a renewal names the holder and epoch it believes in, a takeover the
//! exact `(epoch, beat)` it watched stand still.
//!
//! # The fence and its row locks
//!
//! The promise: **a node that lost the lease never commits a dispatch write.** Every fenced
//! write transaction first runs [`fence`], which reads the lease row `FOR KEY SHARE` and
//! checks its epoch; the lock is held until the transaction ends. A takeover ([`take`])
//! locks the row `FOR UPDATE` before it changes it, and `FOR UPDATE` is the one row lock
//! that conflicts with `FOR KEY SHARE` (PostgreSQL's row-level lock table). So a takeover
//! waits for every fenced transaction that read the row before it, and a fence that reads
//! the row after the takeover committed sees the new epoch and refuses: a write made under
//! the fence is committed before the new node starts, or not at all. (The new node's
//! reconciliation then reads it, as after a restart.) A fenced transaction cut off
//! mid-way is ended by the server (`store::engine::connect`), so it cannot hold a takeover
//! for ever.
//!
//! A renewal ([`renew`]) and a release ([`release`]) change neither `name` (the only key
//! column: the primary key, and no other unique index) nor take any explicit lock, so
//! PostgreSQL takes `FOR NO KEY UPDATE` for them, which does not conflict with `FOR KEY
//! SHARE`: **a renewal is never queued behind an open write transaction**. It once was:
//! the fence read the row `FOR SHARE`, which conflicts with every `UPDATE`, and a writer
//! transaction waiting on the other node's writer (their advisory lock) held the active
//! node's renewal back for up to a second, past its lease, under a loaded failover test.
//! The lease's timing argument (`service::cluster`) assumes a renewal takes a round trip,
//! not the length of somebody's transaction.
//!
//! Neither of those changes can let a stale write through. A renewal keeps the epoch, so a
//! fence that passed still names the holder. A release lets a standby take over at once,
//! but that takeover still waits, `FOR UPDATE`, for the fenced transactions in flight. When
//! a renewal or a release makes a new version of a row a fenced transaction holds `FOR KEY
//! SHARE`, PostgreSQL carries that lock to the new version (so that a foreign key stays
//! valid across non-key updates), which is the version a later takeover locks: it still
//! waits. `tests/it/standby/cluster.rs` checks each of these against a real server: a
//! renewal and a release pass an open fenced transaction, a takeover after them waits for
//! it, and a fence after the takeover refuses the old epoch.

use sqlx::{PgConnection, PgPool};

/// The one lease a cluster has: the right to drive the machines.
pub const LEASE: &str = "dispatch";

/// The lease row as a node reads it.
#[derive(Clone, Debug, PartialEq, Eq, sqlx::FromRow)]
pub struct LeaseRow {
    /// The node that holds (or last held) it.
    pub holder: String,
    /// The fencing token: one more at every takeover.
    pub epoch: i64,
    /// Renewals since the last takeover.
    pub beat: i64,
    /// Let go by a holder that stopped cleanly.
    pub released: bool,
    /// The last renewal, ms since 1970 by the server's clock (for display).
    pub renewed_at: i64,
}

const NOW_MS: &str = "(extract(epoch from clock_timestamp()) * 1000)::bigint";

/// The lease `name`, if anyone ever held it.
pub async fn read(pool: &PgPool, name: &str) -> Result<Option<LeaseRow>, sqlx::Error> {
    sqlx::query_as("SELECT holder, epoch, beat, released, renewed_at FROM cluster_lease WHERE name = $1")
        .bind(name)
        .fetch_optional(pool)
        .await
}

/// Takes the lease for `node`: the first claim ever (epoch 1), or over `seen`, the row as
/// the caller watched it stand still (or released). Returns the new epoch, or None when
/// someone else got there first.
pub async fn take(
    pool: &PgPool,
    name: &str,
    node: &str,
    seen: Option<&LeaseRow>,
) -> Result<Option<i64>, sqlx::Error> {
    let Some(seen) = seen else {
        let sql = format!(
            "INSERT INTO cluster_lease (name, holder, epoch, beat, renewed_at) VALUES ($1, $2, 1, 0, {NOW_MS}) \
             ON CONFLICT (name) DO NOTHING RETURNING epoch"
        );
        return sqlx::query_scalar(sqlx::AssertSqlSafe(sql)).bind(name).bind(node).fetch_optional(pool).await;
    };
    // `FOR UPDATE` first: a plain UPDATE of non-key columns would lock `FOR NO KEY
    // UPDATE`, which passes the fence's `FOR KEY SHARE` (see the module doc). The row is
    // compared in the lock's query too, so a row changed while it waited (read again once
    // the lock is granted) is not taken.
    let sql = format!(
        "WITH watched AS (SELECT name FROM cluster_lease \
         WHERE name = $1 AND epoch = $3 AND beat = $4 AND released = $5 FOR UPDATE) \
         UPDATE cluster_lease SET holder = $2, epoch = epoch + 1, beat = 0, released = FALSE, renewed_at = {NOW_MS} \
         FROM watched WHERE cluster_lease.name = watched.name \
         AND epoch = $3 AND beat = $4 AND released = $5 RETURNING epoch"
    );
    sqlx::query_scalar(sqlx::AssertSqlSafe(sql))
        .bind(name)
        .bind(node)
        .bind(seen.epoch)
        .bind(seen.beat)
        .bind(seen.released)
        .fetch_optional(pool)
        .await
}

/// Renews the lease `node` holds at `epoch`; false when it no longer does.
pub async fn renew(pool: &PgPool, name: &str, node: &str, epoch: i64) -> Result<bool, sqlx::Error> {
    let sql = format!(
        "UPDATE cluster_lease SET beat = beat + 1, renewed_at = {NOW_MS} \
         WHERE name = $1 AND holder = $2 AND epoch = $3 AND NOT released"
    );
    let done = sqlx::query(sqlx::AssertSqlSafe(sql)).bind(name).bind(node).bind(epoch).execute(pool).await?;
    Ok(done.rows_affected() == 1)
}

/// Lets go of the lease `node` holds at `epoch`, so a standby takes over at once.
pub async fn release(pool: &PgPool, name: &str, node: &str, epoch: i64) -> Result<bool, sqlx::Error> {
    let sql = "UPDATE cluster_lease SET released = TRUE WHERE name = $1 AND holder = $2 AND epoch = $3";
    let done = sqlx::query(sql).bind(name).bind(node).bind(epoch).execute(pool).await?;
    Ok(done.rows_affected() == 1)
}

/// Inside a write transaction: whether `epoch` still holds the lease. The row is locked
/// `FOR KEY SHARE` until the transaction ends, so a takeover (`FOR UPDATE`) waits for the
/// commit while a renewal does not: a write made under this check is either committed
/// before the new node starts, or not at all (the module doc has the argument).
pub async fn fence(tx: &mut PgConnection, name: &str, epoch: i64) -> Result<bool, sqlx::Error> {
    let sql = "SELECT epoch FROM cluster_lease WHERE name = $1 AND NOT released FOR KEY SHARE";
    let now: Option<i64> = sqlx::query_scalar(sql).bind(name).fetch_optional(tx).await?;
    Ok(now == Some(epoch))
}

/// A node as it last told of itself.
#[derive(Clone, Debug, PartialEq, Eq, sqlx::FromRow)]
pub struct NodeRow {
    /// Its name (`[cluster] node`).
    pub name: String,
    /// Where its API is reached.
    pub url: String,
    /// `active` or `standby`, as it last said.
    pub role: String,
    /// When it started, ms since 1970 by the server's clock.
    pub started_at: i64,
    /// When it last told, ms since 1970 by the server's clock.
    pub seen_at: i64,
    /// The hash of the `[site]` and `[[devices]]` it runs (empty: not told).
    pub config_hash: String,
    /// Its binary's version (empty: a node of a release before it was told).
    pub version: String,
    /// The schema it knows: the newest migration compiled into it (0: not told).
    pub schema_version: i64,
}

/// What a node tells of itself besides its name.
#[derive(Clone, Copy, Debug)]
pub struct Told<'a> {
    /// Where its API is reached.
    pub url: &'a str,
    /// `active` or `standby`.
    pub role: &'a str,
    /// When it started, ms since 1970.
    pub started_at: i64,
    /// The hash of the configuration it runs.
    pub config_hash: &'a str,
}

/// Tells the cluster that `node` is alive, as `told`, running the binary `version.0`
/// that knows the schema `version.1`.
pub async fn tell(
    pool: &PgPool,
    node: &str,
    told: &Told<'_>,
    version: (&str, i64),
) -> Result<(), sqlx::Error> {
    let sql = format!(
        "INSERT INTO cluster_nodes (name, url, role, started_at, seen_at, config_hash, version, schema_version) \
         VALUES ($1, $2, $3, $4, {NOW_MS}, $5, $6, $7) \
         ON CONFLICT (name) DO UPDATE SET url = $2, role = $3, started_at = $4, seen_at = {NOW_MS}, \
         config_hash = $5, version = $6, schema_version = $7"
    );
    sqlx::query(sqlx::AssertSqlSafe(sql))
        .bind(node)
        .bind(told.url)
        .bind(told.role)
        .bind(told.started_at)
        .bind(told.config_hash)
        .bind(version.0)
        .bind(version.1)
        .execute(pool)
        .await?;
    Ok(())
}

/// Every node that ever told, by name, and the server's clock now (ms).
pub async fn nodes(pool: &PgPool) -> Result<(Vec<NodeRow>, i64), sqlx::Error> {
    let rows = sqlx::query_as(
        "SELECT name, url, role, started_at, seen_at, config_hash, version, schema_version FROM cluster_nodes \
         ORDER BY name",
    )
    .fetch_all(pool)
    .await?;
    let now = sqlx::query_scalar(sqlx::AssertSqlSafe(format!("SELECT {NOW_MS}"))).fetch_one(pool).await?;
    Ok((rows, now))
}
