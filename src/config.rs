//! Configuration: one TOML file, every key documented in `config/rackd.example.toml`.
//!
//! With no file, [`Config::demo`] describes the demo site. Unknown keys are errors, so a
//! typo is reported with its key and line rather than silently ignored.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

mod check;
mod events;

pub use check::Invalid;
pub use events::{EventsConfig, EventsConfigError};

pub use crate::auth::{AuthConfig, KeyConfig};
use crate::domain::{AisleLayout, Layout};

/// The whole configuration file.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// The HTTP server.
    pub server: ServerConfig,
    /// The SQLite database.
    pub database: DatabaseConfig,
    /// Job intake (group commit).
    pub intake: IntakeConfig,
    /// API keys.
    pub auth: AuthConfig,
    /// The site's layout.
    pub site: SiteConfig,
    /// The event log and live subscribers.
    pub events: EventsConfig,
    /// The machines, one `[[devices]]` entry each.
    pub devices: Vec<crate::devices::DeviceConfig>,
}

/// `[server]`
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServerConfig {
    /// Address and port to serve on.
    pub listen: SocketAddr,
    /// Largest accepted request body in bytes.
    pub body_limit_bytes: usize,
    /// Seconds a request may take before it is answered 503.
    pub request_timeout_secs: u64,
}

/// `[database]`
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DatabaseConfig {
    /// Path of the SQLite file; its folder is created if missing.
    pub path: PathBuf,
    /// How long a statement waits for a lock before failing, in milliseconds.
    pub busy_timeout_ms: u64,
}

/// `[intake]`: how job submissions are committed.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntakeConfig {
    /// Most requests committed in one transaction.
    pub max_group: usize,
    /// Requests waiting for the writer before new ones are refused with 503.
    pub queue: usize,
}

/// `[site]`: which locations exist.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteConfig {
    /// One `[[site.aisles]]` entry per aisle.
    pub aisles: Vec<AisleConfig>,
}

/// One `[[site.aisles]]` entry.
#[derive(Clone, Debug, PartialEq, Deserialize)]
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
}

impl AisleConfig {
    /// The aisle's size as the domain sees it.
    pub fn layout(&self) -> AisleLayout {
        AisleLayout { rows: self.rows, bays: self.bays, levels: self.levels, positions: self.positions }
    }
}

/// A configuration that could not be loaded, with the key and line when known.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not valid TOML or has a wrong or unknown key.
    #[error("{path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's error, naming the key and line.
        source: toml::de::Error,
    },
    /// The values are valid TOML but make no sense together.
    #[error("{path}: {source}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        source: Invalid,
    },
}

impl Config {
    /// The demo site: shelf aisle 1 of 2 rows x 10 bays x 6 levels x 4 positions, and
    /// crane aisle 2 of 2 rows x 20 bays x 8 levels x 2 depths (sides).
    pub fn demo() -> Self {
        let mut config = Config::default();
        config.site.aisles.push(AisleConfig { aisle: 2, rows: 2, bays: 20, levels: 8, positions: 2 });
        config
    }

    /// Loads and checks a configuration file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| ConfigError::Read { path: path.to_owned(), source })?;
        Self::parse(&text, path)
    }

    /// Parses and checks configuration text; `path` is only used in messages.
    pub fn parse(text: &str, path: &Path) -> Result<Config, ConfigError> {
        let config: Config =
            toml::from_str(text).map_err(|source| ConfigError::Parse { path: path.to_owned(), source })?;
        config.check().map_err(|source| ConfigError::Invalid { path: path.to_owned(), source })?;
        Ok(config)
    }

    /// The site layout that locations are checked against.
    pub fn layout(&self) -> Layout {
        Layout::new(self.site.aisles.iter().map(|a| (a.aisle, a.layout())).collect::<BTreeMap<_, _>>())
    }
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            body_limit_bytes: 2 * 1024 * 1024,
            request_timeout_secs: 30,
        }
    }
}

impl Default for DatabaseConfig {
    fn default() -> Self {
        DatabaseConfig { path: PathBuf::from("data/rackd.db"), busy_timeout_ms: 5000 }
    }
}

impl Default for IntakeConfig {
    fn default() -> Self {
        IntakeConfig { max_group: 2048, queue: 16384 }
    }
}

impl Default for SiteConfig {
    fn default() -> Self {
        SiteConfig { aisles: vec![AisleConfig { aisle: 1, rows: 2, bays: 10, levels: 6, positions: 4 }] }
    }
}

#[cfg(test)]
mod tests;
