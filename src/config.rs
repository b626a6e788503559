//! Configuration: one TOML file, every key documented in `config/rackd.example.toml`.
//!
//! With no file, [`Config::demo`] describes the demo site. Unknown keys are errors, so a
//! typo is reported with its key and line rather than silently ignored.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

mod events;

pub use events::EventsConfig;

use crate::auth::KeyHash;
use crate::domain::{AisleLayout, Layout};

/// The whole configuration file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
#[derive(Default)]
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
#[derive(Clone, Debug, Deserialize)]
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
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DatabaseConfig {
    /// Path of the SQLite file; its folder is created if missing.
    pub path: PathBuf,
    /// How long a statement waits for a lock before failing, in milliseconds.
    pub busy_timeout_ms: u64,
}

/// `[intake]`: how job submissions are committed.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntakeConfig {
    /// Most requests committed in one transaction.
    pub max_group: usize,
    /// Requests waiting for the writer before new ones are refused with 503.
    pub queue: usize,
}

/// `[auth]`
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AuthConfig {
    /// The API keys, stored hashed (`rackd hash-key` prints a hash).
    pub keys: Vec<KeyConfig>,
}

/// One `[[auth.keys]]` entry.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyConfig {
    /// Who holds the key, for logs.
    pub name: String,
    /// `viewer`, `operator` or `admin`.
    pub role: crate::auth::Role,
    /// `sha256:` and the hex SHA-256 of the key.
    pub hash: KeyHash,
}

/// `[site]`: which locations exist.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteConfig {
    /// One `[[site.aisles]]` entry per aisle.
    pub aisles: Vec<AisleConfig>,
}

/// One `[[site.aisles]]` entry.
#[derive(Clone, Debug, Deserialize)]
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
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, naming the key and line.
        message: String,
    },
    /// The values are valid TOML but make no sense together.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
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
        let config: Config = toml::from_str(text)
            .map_err(|e| ConfigError::Parse { path: path.to_owned(), message: e.to_string() })?;
        config.check().map_err(|message| ConfigError::Invalid { path: path.to_owned(), message })?;
        Ok(config)
    }

    fn check(&self) -> Result<(), String> {
        let mut seen = std::collections::BTreeSet::new();
        for a in &self.site.aisles {
            if a.aisle == 0 || !seen.insert(a.aisle) {
                return Err(format!("site.aisles: aisle {} is zero or listed twice", a.aisle));
            }
            let l = a.layout();
            if !(1..=2).contains(&l.rows) || l.bays == 0 || l.levels == 0 || l.positions == 0 {
                return Err(format!(
                    "site.aisles: aisle {} needs rows 1..=2 and at least one bay, level and position",
                    a.aisle
                ));
            }
        }
        if self.site.aisles.is_empty() {
            return Err("site.aisles: at least one aisle is needed".into());
        }
        let mut ids = std::collections::BTreeSet::new();
        let mut served = std::collections::BTreeMap::new();
        for d in &self.devices {
            d.check()?;
            if !ids.insert(d.id.as_str()) {
                return Err(format!("devices: id {:?} is used twice", d.id));
            }
            for &aisle in &d.aisles {
                if !seen.contains(&aisle) {
                    return Err(format!("devices {:?}: aisle {aisle} is not in site.aisles", d.id));
                }
                if let Some(other) = served.insert(aisle, d.id.as_str()) {
                    return Err(format!("devices {:?}: aisle {aisle} is already served by {other:?}", d.id));
                }
            }
        }
        if self.intake.max_group == 0 || self.intake.queue == 0 {
            return Err("intake.max_group and intake.queue must be at least 1".into());
        }
        self.events.check()
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
mod tests {
    use super::*;

    #[test]
    fn the_example_file_loads() {
        let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/config/rackd.example.toml"));
        let config = Config::load(path).unwrap();
        assert_eq!(config.auth.keys.len(), 3);
    }

    #[test]
    fn unknown_key_is_named_with_its_line() {
        let err = Config::parse("[server]\nlisten = \"127.0.0.1:1\"\nlissen = 3\n", Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("lissen") && err.contains("line 3"), "{err}");
    }

    #[test]
    fn a_tags_device_table_follows_its_entry() {
        let text = "[[devices]]\nid = \"tower1\"\nkind = \"tags\"\nprotocol = \"ppi-tcp\"\naddress = \"10.0.0.2:102\"\nunit = 2\n\
                    [devices.tags]\nbeacon.red = \"Q0.1\"\n\"conveyor.speed\" = { address = \"VD4\", type = \"f32\", max = 2.5 }\n";
        let config = Config::parse(text, Path::new("x.toml")).unwrap();
        assert_eq!(config.devices[0].tags.0.len(), 2);
        let bad = text.replace("max = 2.5", "mx = 2.5");
        let err = Config::parse(&bad, Path::new("x.toml")).unwrap_err().to_string();
        assert!(err.contains("conveyor.speed") && err.contains("mx") && err.contains("line"), "{err}");
        let bad = text.replace("VD4", "VD4.1");
        let err = Config::parse(&bad, Path::new("x.toml")).unwrap_err().to_string();
        assert!(err.contains("tower1") && err.contains("conveyor.speed") && err.contains("VD4.1"), "{err}");
    }

    #[test]
    fn bad_layout_is_refused() {
        let text = "[[site.aisles]]\naisle = 1\nrows = 3\nbays = 1\nlevels = 1\npositions = 1\n";
        let err = Config::parse(text, Path::new("x.toml")).unwrap_err().to_string();
        assert!(err.contains("rows"), "{err}");
    }
}
