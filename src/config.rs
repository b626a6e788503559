//! Configuration: every key documented in `config/rackd.example.toml`, in layers
//! (lowest first): the defaults, one TOML file, the environment (`RACKD_<SECTION>__<KEY>`,
//! see [`env`](mod@env)), the command line (`--listen`, `--database`). [`layers`] merges them with
//! figment and says where each value came from ([`Origin`]).
//!
//! Every device's settings are here too ([`devices`]: one `[[devices]]` entry per machine,
//! a [`devices::DeviceConfig`] per kind), so the configuration is checked whole without
//! the adapters that use it.
//!
//! With no file, [`Config::demo`] describes the demo site (the environment and command
//! line still apply). Unknown keys are errors, in the file and in the environment, so a
//! typo is reported with its key and line (or variable) rather than silently ignored.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub mod ca;
mod check;
pub mod devices;
pub mod diff;
pub mod env;
mod error;
mod events;
mod explain;
mod hosts;
pub mod layers;
pub mod origin;
mod retention;
pub mod tls;
mod warnings;
pub mod webhooks;

pub use check::Invalid;
pub use diff::{Change, Difference, RELOAD_ACTION, RunningConfig};
pub use env::EnvError;
pub use error::ConfigError;
pub use events::{EventsConfig, EventsConfigError};
pub use hosts::{AllowedHost, BadHost};
pub use layers::{Loaded, Sources};
pub use origin::Origin;
pub use retention::{ARCHIVE_ACTION, RetentionConfig};
pub use tls::{TlsConfig, TlsError};
pub use warnings::{Warning, in_clear};
pub use webhooks::WebhookConfig;

pub use crate::auth::{AuthConfig, KeyConfig};
use crate::domain::{AisleLayout, Layout};
use devices::{DeviceConfig, RawDevice};

/// The whole configuration file.
#[derive(Clone, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// The HTTP server.
    pub server: ServerConfig,
    /// The database: a SQLite file (the default) or a PostgreSQL server.
    pub database: DatabaseConfig,
    /// Job intake (group commit).
    pub intake: IntakeConfig,
    /// API keys.
    pub auth: AuthConfig,
    /// The site's layout.
    pub site: SiteConfig,
    /// The event log and live subscribers.
    pub events: EventsConfig,
    /// How long ended jobs stay in the store, and where the archive is.
    pub retention: RetentionConfig,
    /// Hot standby: this node is one of several on one PostgreSQL database
    /// (`service::cluster`). None: a node of its own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cluster: Option<ClusterConfig>,
    /// The machines, one `[[devices]]` entry each.
    #[serde(serialize_with = "flat_devices")]
    pub devices: Vec<DeviceConfig>,
    /// Subscriptions that push events to a WMS, one `[[webhooks]]` entry each.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub webhooks: Vec<WebhookConfig>,
}

/// Devices written as the file writes them, every key of their kind filled in.
fn flat_devices<S: serde::Serializer>(devices: &[DeviceConfig], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(devices.iter().map(RawDevice::from))
}

/// `[server]`
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServerConfig {
    /// Address and port to serve on.
    pub listen: SocketAddr,
    /// Largest accepted request body in bytes.
    pub body_limit_bytes: usize,
    /// Seconds a request may take before it is answered 503.
    pub request_timeout_secs: u64,
    /// Without API keys: more names (`NAME` at any port, or `NAME:PORT`) the `Host` and
    /// `Origin` of a request may give besides `localhost`, `127.0.0.1`, `[::1]` and the
    /// listen address at the listen port (see `api::keyless`). From the environment: a
    /// comma-separated list.
    #[serde(deserialize_with = "hosts::list_or_commas")]
    pub allowed_hosts: Vec<AllowedHost>,
    /// Milliseconds a connection has to send a request's headers: from its accept (the TLS
    /// handshake included) for the first request, from its first byte for each next one.
    pub header_timeout_ms: u64,
    /// Milliseconds a keep-alive connection may wait for its next request before it is
    /// closed (and a response may wait for a client that does not read it).
    pub idle_timeout_ms: u64,
    /// Most connections open at once, WebSockets included; at the cap, a new connection
    /// takes the place of the one that has waited longest without being served
    /// (`app::serve` says why).
    pub max_connections: usize,
    /// Device captures (`GET /api/v1/devices/{id}/capture`) built at once; one more is
    /// answered 429 `capture_busy` with `Retry-After` (`api::devices::capture`).
    pub capture_downloads: usize,
    /// HTTPS and WSS instead of HTTP and WS on `listen`; plain HTTP when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tls: Option<TlsConfig>,
}

/// `[database]`
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DatabaseConfig {
    /// Path of the SQLite file; its folder is created if missing. Not used when `url` is set.
    pub path: PathBuf,
    /// A PostgreSQL server instead of the SQLite file: `postgres://user:password@host/db`
    /// (any libpq-style URL sqlx accepts, with `?sslmode=` and the rest). A secret: shown
    /// without its password wherever configuration is printed.
    pub url: Option<String>,
    /// A file whose content (trimmed) is `url`, for a container secret
    /// (`/run/secrets/database_url`); exactly one of `url` and `url_file`. Once loaded,
    /// `url` holds what the file says.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub url_file: Option<PathBuf>,
    /// The CA (PEM) a PostgreSQL server's certificate is checked against, for
    /// `sslmode=verify-ca` and `verify-full` (`store::engine` says how the mode is chosen).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ca_file: Option<PathBuf>,
    /// The SQLite VFS the file is opened through, by the name it is registered under in
    /// the process; SQLite's default when not set (`store::engine::Settings::vfs`). For
    /// a program that runs rackd's library with a VFS of its own, as the fault tests do.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sqlite_vfs: Option<String>,
    /// How long a statement waits for a lock before failing, in milliseconds.
    pub busy_timeout_ms: u64,
    /// Tests only, never read from a file: the node knows the migrations up to this
    /// version only, as a node of an earlier release would (`store::schema::Known::up_to`;
    /// tests/it/standby/upgrade.rs). The code is still this release's.
    #[serde(skip)]
    pub known_schema: Option<i64>,
}

/// `[intake]`: how job submissions are committed.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntakeConfig {
    /// Most requests committed in one transaction.
    pub max_group: usize,
    /// Requests waiting for the writer before new ones are refused with 503.
    pub queue: usize,
}

/// `[cluster]`: this node's part in a hot-standby cluster (PostgreSQL only).
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterConfig {
    /// This node's name, unique in the cluster (`a`, `rackd-2`, ...).
    pub node: String,
    /// How long a lease renewal lets the active node drive the machines (ms).
    #[serde(default = "lease_ms")]
    pub lease_ms: u64,
    /// What a standby waits beyond the lease before it takes over (ms); a fifth of the
    /// lease when not set.
    #[serde(default)]
    pub margin_ms: Option<u64>,
    /// The URL other nodes reach this node's API at, to forward what only the active node
    /// does; `http://` (`https://` with `[server.tls]`) + `server.listen` when not set.
    #[serde(default)]
    pub url: Option<String>,
    /// The CA (PEM) this node trusts when it forwards to another node over `https://`;
    /// when not set, the public roots compiled in (webpki-roots).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ca_file: Option<PathBuf>,
}

fn lease_ms() -> u64 {
    5000
}

impl ClusterConfig {
    /// The lease and the margin.
    pub fn lease(&self) -> (std::time::Duration, std::time::Duration) {
        let lease = std::time::Duration::from_millis(self.lease_ms);
        (lease, self.margin_ms.map_or(lease / 5, std::time::Duration::from_millis))
    }

    /// Where other nodes reach this node's API: `http://` + `listen`, or `https://` when
    /// `tls` (the node serves `[server.tls]`), unless `url` says.
    pub fn url(&self, listen: SocketAddr, tls: bool) -> String {
        let scheme = if tls { "https" } else { "http" };
        self.url.clone().unwrap_or_else(|| format!("{scheme}://{listen}"))
    }
}

/// `[site]`: which locations exist.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SiteConfig {
    /// One `[[site.aisles]]` entry per aisle.
    pub aisles: Vec<AisleConfig>,
    /// One `[[site.stations]]` entry per station sequences go to: how long a box takes from
    /// each aisle's exit to it (see `service::dispatch::gate`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stations: Vec<StationConfig>,
}

/// One `[[site.stations]]` entry: a station the members of a sequence reach in order.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StationConfig {
    /// The station's number, from 1, as a sequence's `station` names it.
    pub id: u16,
    /// What people call it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Seconds a box takes from each aisle's exit (where its crane or shelf hands it out) to
    /// the station; an aisle not listed takes 0.
    #[serde(default)]
    pub transit: Vec<Transit>,
}

/// One aisle's transit time to a station.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Transit {
    /// The aisle.
    pub aisle: u16,
    /// Seconds from its exit to the station.
    pub seconds: f64,
}

impl StationConfig {
    /// Seconds from `aisle`'s exit to the station (0 for an aisle not listed).
    pub fn transit_s(&self, aisle: u16) -> f64 {
        self.transit.iter().find(|t| t.aisle == aisle).map_or(0.0, |t| t.seconds)
    }
}

/// One `[[site.aisles]]` entry.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AisleConfig {
    /// The aisle's number, from 1.
    pub aisle: u16,
    /// Rows (1 = A, 2 = B).
    pub rows: u16,
    /// Bays along the aisle (bay 0 is the station and always exists).
    pub bays: u16,
    /// Levels per bay.
    pub levels: u16,
    /// Box positions (shelf) or depths (crane) per level.
    pub positions: u16,
    /// 2: a double-deep crane aisle (position 1 near, 2 far behind it), where rackd keeps
    /// the crane from ever being asked to reach past a box (see `service::planner`); 1
    /// (the default): no such rules.
    #[serde(default = "single_deep")]
    pub depth: u16,
}

fn single_deep() -> u16 {
    1
}

impl AisleConfig {
    /// The aisle's size as the domain sees it.
    pub fn layout(&self) -> AisleLayout {
        AisleLayout { rows: self.rows, bays: self.bays, levels: self.levels, positions: self.positions }
    }
}

impl Config {
    /// The demo site: shelf aisle 1 of 2 rows x 10 bays x 6 levels x 4 positions, and
    /// crane aisle 2 of 2 rows x 20 bays x 8 levels x 2 depths (sides).
    pub fn demo() -> Self {
        let mut config = Config::default();
        config.site.aisles.push(AisleConfig {
            aisle: 2,
            rows: 2,
            bays: 20,
            levels: 8,
            positions: 2,
            depth: 2,
        });
        config
    }

    /// Loads and checks a configuration file alone: no environment, no command line.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        Ok(Sources::file(path).load()?.config)
    }

    /// Parses and checks configuration text alone; `path` is only used in messages.
    pub fn parse(text: &str, path: &Path) -> Result<Config, ConfigError> {
        Ok(Sources::file(path).load_text(Some(text.to_owned()))?.config)
    }

    /// The site layout that locations are checked against.
    pub fn layout(&self) -> Layout {
        Layout::new(self.site.aisles.iter().map(|a| (a.aisle, a.layout())).collect::<BTreeMap<_, _>>())
    }
}

/// The default of `server.body_limit_bytes`: the largest request body, 2 MiB.
pub const BODY_LIMIT: usize = 2 * 1024 * 1024;

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            body_limit_bytes: BODY_LIMIT,
            request_timeout_secs: 30,
            allowed_hosts: Vec::new(),
            header_timeout_ms: 10_000,
            idle_timeout_ms: 60_000,
            max_connections: 1024,
            capture_downloads: 2,
            tls: None,
        }
    }
}

impl Default for DatabaseConfig {
    fn default() -> Self {
        DatabaseConfig {
            path: PathBuf::from("data/rackd.db"),
            url: None,
            url_file: None,
            ca_file: None,
            sqlite_vfs: None,
            busy_timeout_ms: 5000,
            known_schema: None,
        }
    }
}

impl Default for IntakeConfig {
    fn default() -> Self {
        IntakeConfig { max_group: 2048, queue: 16384 }
    }
}

impl Default for SiteConfig {
    fn default() -> Self {
        SiteConfig {
            aisles: vec![AisleConfig { aisle: 1, rows: 2, bays: 10, levels: 6, positions: 4, depth: 1 }],
            stations: Vec::new(),
        }
    }
}

/// The database URL in the file at `path` (`database.url_file`): its content, trimmed.
pub fn read_url_file(path: &Path) -> Result<String, UrlFileError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| UrlFileError::Read { path: path.to_owned(), source })?;
    match text.trim() {
        "" => Err(UrlFileError::Empty(path.to_owned())),
        url => Ok(url.to_owned()),
    }
}

/// Why `database.url_file` gives no URL. No variant holds the file's content.
#[derive(Debug, thiserror::Error)]
pub enum UrlFileError {
    /// The file cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file holds nothing but white space.
    #[error("{} is empty (expected the URL: postgres://...)", .0.display())]
    Empty(PathBuf),
    /// `database.url` is set as well, at this place.
    #[error("database.url is set too (at {0}): keep one of the two")]
    AlsoUrl(Origin),
}

#[cfg(test)]
mod layers_tests;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod webhooks_tests;
