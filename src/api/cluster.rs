//! `GET /api/v1/cluster`: the nodes of a hot-standby cluster, their roles, the lease's
//! epoch and age (see `service::cluster`), and each node's version and schema (a site
//! upgrading one node at a time runs two releases; `store::schema`). A node of its own
//! answers 404.

use axum::extract::State;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::{router::OpenApiRouter, routes};

use super::error::{ApiError, ErrorBody};
use super::extract::Json;
use super::state::AppState;
use crate::domain::time::from_ms;

/// The routes of this resource.
pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(cluster))
}

/// The cluster as the answering node sees it.
#[derive(Debug, Serialize, ToSchema)]
#[schema(example = json!({"node": "b", "role": "active", "epoch": 4, "takeovers": 1,
    "lease": {"holder": "b", "epoch": 4, "age_ms": 640, "released": false, "lease_ms": 5000, "margin_ms": 1000},
    "nodes": [{"name": "a", "url": "http://10.0.0.11:8080", "role": "standby", "seen_ms_ago": 900,
        "started_at": "2026-11-24T07:00:00Z", "config_hash": "9f2c4e0d3b8a7f61e5d2c9b0a4f7e3d1c8b6a5f4e3d2c1b0a9f8e7d6c5b4a3f2",
        "version": "0.2.0", "schema": 14},
        {"name": "b", "url": "http://10.0.0.12:8080", "role": "active", "seen_ms_ago": 300,
        "started_at": "2026-11-20T07:00:00Z", "config_hash": "9f2c4e0d3b8a7f61e5d2c9b0a4f7e3d1c8b6a5f4e3d2c1b0a9f8e7d6c5b4a3f2",
        "version": "0.1.0", "schema": 13}],
    "config_hash": "9f2c4e0d3b8a7f61e5d2c9b0a4f7e3d1c8b6a5f4e3d2c1b0a9f8e7d6c5b4a3f2", "config_drift": false,
    "version": "0.1.0", "schema": 13, "database_schema": 14}))]
pub struct ClusterView {
    /// The answering node.
    pub node: String,
    /// Its role: `active` (it drives the machines) or `standby`.
    pub role: &'static str,
    /// The epoch it drives under (active only).
    pub epoch: Option<i64>,
    /// Times this node's process took over.
    pub takeovers: u64,
    /// The lease, if any node ever held it.
    pub lease: Option<LeaseView>,
    /// Every node that ever told of itself, by name.
    pub nodes: Vec<NodeView>,
    /// The hash of the `[site]` and `[[devices]]` the answering node runs.
    pub config_hash: String,
    /// Whether a node seen within two leases runs another configuration (the active node
    /// raises `config_drift` then).
    pub config_drift: bool,
    /// The answering node's version.
    pub version: &'static str,
    /// The schema the answering node knows: the newest migration compiled into it.
    pub schema: i64,
    /// The newest migration applied in the database. Newer than `schema` while a newer
    /// node migrated it: this node runs on it because each newer migration is recorded
    /// compatible with its schema (it refuses to start otherwise).
    pub database_schema: i64,
}

/// The lease.
#[derive(Debug, Serialize, ToSchema)]
pub struct LeaseView {
    /// The node that holds it (or last held it).
    pub holder: String,
    /// The fencing token: one more at every takeover.
    pub epoch: i64,
    /// Milliseconds since its last renewal, by the database server's clock.
    pub age_ms: i64,
    /// Let go by a node that stopped cleanly.
    pub released: bool,
    /// How long a renewal lets the active node drive.
    pub lease_ms: u64,
    /// What a standby waits beyond the lease before it takes over.
    pub margin_ms: u64,
}

/// A node as it last told of itself.
#[derive(Debug, Serialize, ToSchema)]
pub struct NodeView {
    /// Its name.
    pub name: String,
    /// Where its API is reached.
    pub url: String,
    /// `active` or `standby`, as it last told.
    pub role: String,
    /// Milliseconds since it last told (a node that stopped ages).
    pub seen_ms_ago: i64,
    /// When its process started.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub started_at: time::OffsetDateTime,
    /// The hash of the `[site]` and `[[devices]]` it runs, as it last told (empty: not
    /// told).
    pub config_hash: String,
    /// Its binary's version, as it last told (empty: not told).
    pub version: String,
    /// The schema it knows, the newest migration compiled into it, as it last told (0: not
    /// told).
    pub schema: i64,
}

/// The cluster's nodes, roles, epoch and lease age.
#[utoipa::path(get, path = "/cluster", tag = "operations",
    responses(
        (status = 200, description = "The cluster", body = ClusterView),
        (status = 401, description = "No key, or an unknown key", body = ErrorBody),
        (status = 404, description = "This node is not in a cluster", body = ErrorBody),
        (status = 503, description = "The database does not answer", body = ErrorBody),
    ))]
async fn cluster(State(app): State<AppState>) -> Result<Json<ClusterView>, ApiError> {
    let Some(node) = &app.cluster else {
        return Err(ApiError::not_found("this node is not in a cluster ([cluster] is not configured)"));
    };
    let view = node.view().await.map_err(ApiError::unavailable)?;
    let config_drift = !node.drift(&view).is_empty();
    let lease = view.lease.map(|l| LeaseView {
        holder: l.holder,
        epoch: l.epoch,
        age_ms: (view.now - l.renewed_at).max(0),
        released: l.released,
        lease_ms: node.timing.lease.as_millis() as u64,
        margin_ms: node.timing.margin.as_millis() as u64,
    });
    let nodes = view
        .nodes
        .into_iter()
        .map(|n| NodeView {
            name: n.name,
            url: crate::redact::url(&n.url),
            role: n.role,
            seen_ms_ago: (view.now - n.seen_at).max(0),
            started_at: from_ms(n.started_at),
            config_hash: n.config_hash,
            version: n.version,
            schema: n.schema_version,
        })
        .collect();
    Ok(Json(ClusterView {
        node: node.name.clone(),
        role: node.role_name(),
        epoch: node.role().epoch(),
        takeovers: node.takeovers(),
        lease,
        nodes,
        config_hash: node.config.borrow().hash.clone(),
        config_drift,
        version: crate::service::cluster::node::VERSION,
        schema: node.schema,
        database_schema: view.schema,
    }))
}
