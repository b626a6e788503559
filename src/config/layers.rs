//! The layers of the configuration and their order: defaults < file < environment <
//! command line, merged with figment; and where each value came from.
//!
//! figment merges the layers and reports the path of a value it cannot read; the lines
//! come from the file's own keys ([`Lines`]), since figment does not keep them. Without a
//! file, the demo site's layout is the default layer. `auth.keys_file` is read once the
//! layers are merged (it may itself come from the environment), and its keys join
//! `auth.keys`; `database.url_file` likewise, its content becoming `database.url` (whose
//! origin is then the file's first line).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use figment::value::{Dict, Map, Value};
use figment::{Figment, Metadata, Profile, Provider, Source};

use super::devices::DeviceConfig;
use super::env::{self, EnvLayer};
use super::origin::{Lines, join};
use super::{Config, ConfigError, Invalid, Origin, UrlFileError};
use crate::auth::{KeysFile, repeated_key};
use crate::config::devices::RawDevice;

/// Where a configuration comes from.
#[derive(Clone, Debug, Default)]
pub struct Sources {
    /// The file; `None` is the demo site.
    pub file: Option<PathBuf>,
    /// `RACKD_` variables (all of them: the loader picks and checks).
    pub env: Vec<(String, String)>,
    /// `--listen`.
    pub listen: Option<SocketAddr>,
    /// `--database`.
    pub database: Option<PathBuf>,
}

/// A configuration, and where each of its values came from.
#[derive(Debug)]
pub struct Loaded {
    /// The configuration, checked.
    pub config: Config,
    file: Option<Lines>,
    /// `auth.keys_file`'s keys, and how many keys came before them.
    keys_file: Option<(Lines, usize)>,
    /// `database.url_file`, once read into `database.url`.
    url_file: Option<PathBuf>,
    /// (variable, key, value) of each setting from the environment.
    env: Vec<(String, String, String)>,
    cli: Vec<&'static str>,
}

impl Sources {
    /// A file alone.
    pub fn file(path: &Path) -> Sources {
        Sources { file: Some(path.to_owned()), ..Sources::default() }
    }

    /// What `rackd serve` reads: its `--config` (none: the demo site), `--listen`,
    /// `--database` and the `RACKD_` variables of this process. `check-config` reads the
    /// same, with its file; a reload reads the same sources again (`service::reload`).
    pub fn of_process(
        file: Option<PathBuf>,
        listen: Option<SocketAddr>,
        database: Option<PathBuf>,
    ) -> Sources {
        Sources { file, env: Vec::new(), listen, database }.with_process_env()
    }

    /// These sources with the `RACKD_` variables of this process.
    pub fn with_process_env(mut self) -> Sources {
        self.env = env::process_vars();
        self
    }

    /// Reads, merges and checks.
    pub fn load(&self) -> Result<Loaded, ConfigError> {
        self.load_text(None)
    }

    /// As [`Sources::load`], with the file's text given (tests, `Config::parse`).
    pub fn load_text(&self, text: Option<String>) -> Result<Loaded, ConfigError> {
        let env = env::settings(&self.env)?;
        let mut figment = Figment::new();
        let file = match &self.file {
            Some(path) => {
                let text = match text {
                    Some(text) => text,
                    None => read(path)?,
                };
                let lines = Lines::parse(path, &text)?;
                figment = figment.merge(FileLayer { lines: lines.clone(), text });
                Some(lines)
            }
            None => {
                figment = figment.merge(figment::providers::Serialized::default("site", Config::demo().site));
                None
            }
        };
        let cli = Vec::from_iter(
            [("server.listen", self.listen.is_some()), ("database.path", self.database.is_some())]
                .into_iter()
                .filter_map(|(key, set)| set.then_some(key)),
        );
        figment = figment.merge(EnvLayer(env.clone())).merge(CliLayer(self.clone()));
        let mut loaded =
            Loaded { config: Config::default(), file, keys_file: None, url_file: None, env, cli };
        let mut config: Config = figment.extract().map_err(|e| loaded.parse_error(&figment, e))?;
        loaded.add_keys_file(&mut config)?;
        loaded.add_url_file(&mut config)?;
        // Read once, here: a takeover hours later signs and trusts with what they held now.
        for webhook in &mut config.webhooks {
            webhook.resolve();
        }
        let invalid = |(key, source): (String, Invalid), loaded: &Loaded| ConfigError::Invalid {
            origin: Box::new(loaded.locate(&key)),
            key,
            source,
        };
        config.check().map_err(|flaw| invalid(flaw, &loaded))?;
        if let Some((j, i, what)) = repeated_key(&config.auth.keys) {
            let first = loaded.locate(&format!("auth.keys[{i}].{what}"));
            let flaw = (format!("auth.keys[{j}].{what}"), Invalid::KeyTwice { what, first });
            return Err(invalid(flaw, &loaded));
        }
        loaded.config = config;
        Ok(loaded)
    }
}

impl Loaded {
    /// Where the value at `key` was set; `Origin::Default` if nowhere.
    pub fn origin(&self, key: &str) -> Origin {
        self.find(key, false)
    }

    /// Where the value at `key` was set, or else the nearest table or entry around it in
    /// the file (a key left out of an entry points at the entry).
    pub fn locate(&self, key: &str) -> Origin {
        self.find(key, true)
    }

    fn find(&self, key: &str, nearest: bool) -> Origin {
        let look = |lines: &Lines, key: &str| if nearest { lines.nearest(key) } else { lines.find(key) };
        if let (Some(path), "database.url") = (&self.url_file, key) {
            return Origin::File { path: path.clone(), line: 1, column: 1 };
        }
        if self.cli.contains(&key) {
            return Origin::CommandLine;
        }
        if let Some((var, _, _)) = self.env.iter().rev().find(|(_, k, _)| k == key) {
            return Origin::Env(var.clone());
        }
        // An unknown section from the environment (`RACKD_SERVR__LISTEN`) is named by it.
        let within = format!("{key}.");
        if let Some((var, _, _)) = self.env.iter().find(|(_, k, _)| nearest && k.starts_with(&within)) {
            return Origin::Env(var.clone());
        }
        if let (Some((lines, inline)), Some(rest)) = (&self.keys_file, key.strip_prefix("auth.keys[")) {
            let (index, tail) = rest.split_once(']').unwrap_or((rest, ""));
            if let Some(n) = index.parse::<usize>().ok().filter(|n| n >= inline) {
                return look(lines, &format!("keys[{}]{tail}", n - inline)).unwrap_or(Origin::Default);
            }
        }
        self.file.as_ref().and_then(|lines| look(lines, key)).unwrap_or(Origin::Default)
    }

    /// The error for a value figment could not read.
    fn parse_error(&self, figment: &Figment, e: figment::Error) -> ConfigError {
        let mut parts = e.path.clone();
        let mut message = e.kind.to_string();
        if let figment::error::Kind::UnknownField(field, expected) = &e.kind {
            if parts.last() != Some(field) {
                parts.push(field.clone());
            }
            let expected: Vec<String> = expected.iter().map(|k| format!("`{k}`")).collect();
            message = format!("unknown field `{field}`, expected one of {}", expected.join(", "));
        }
        if let [devices, index] = parts.as_slice()
            && let Some((key, why)) = (devices == "devices").then(|| device_problem(figment, index)).flatten()
        {
            parts.push(key);
            message = why;
        }
        let key = join(&parts);
        ConfigError::Parse { origin: Box::new(self.locate(&key)), key, message }
    }

    /// Reads `auth.keys_file` and adds its keys to `auth.keys`.
    fn add_keys_file(&mut self, config: &mut Config) -> Result<(), ConfigError> {
        let Some(path) = config.auth.keys_file.clone() else { return Ok(()) };
        let text = read(&path)?;
        let lines = Lines::parse(&path, &text)?;
        let file = KeysFile::parse(&text).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            let key = lines.key_at(offset).unwrap_or("keys").to_owned();
            ConfigError::Parse {
                origin: Box::new(Origin::in_file(&path, &text, offset)),
                key,
                message: e.message().into(),
            }
        })?;
        if file.keys.is_empty() {
            let key = "auth.keys_file".to_owned();
            return Err(ConfigError::Invalid {
                origin: Box::new(self.locate(&key)),
                key,
                source: Invalid::NoKeysInFile(path),
            });
        }
        self.keys_file = Some((lines, config.auth.keys.len()));
        config.auth.keys.extend(file.keys);
        Ok(())
    }
}

impl Loaded {
    /// Reads `database.url_file` into `database.url`: exactly one of them is set.
    fn add_url_file(&mut self, config: &mut Config) -> Result<(), ConfigError> {
        let Some(path) = config.database.url_file.clone() else { return Ok(()) };
        let key = "database.url_file".to_owned();
        let invalid = |why: UrlFileError, loaded: &Loaded| ConfigError::Invalid {
            origin: Box::new(loaded.locate(&key)),
            key: key.clone(),
            source: Invalid::UrlFile(why),
        };
        if config.database.url.is_some() {
            return Err(invalid(UrlFileError::AlsoUrl(self.locate("database.url")), self));
        }
        let url = super::read_url_file(&path).map_err(|why| invalid(why, self))?;
        config.database.url = Some(url);
        self.url_file = Some(path);
        Ok(())
    }
}

/// The key and message of a `[[devices]]` entry that reads but does not convert (a key of
/// another kind, a unit out of range): figment only knows the entry, the typed error knows
/// the key.
fn device_problem(figment: &Figment, index: &str) -> Option<(String, String)> {
    let Value::Array(_, entries) = figment.find_value("devices").ok()? else { return None };
    let raw: RawDevice = entries.get(index.parse::<usize>().ok()?)?.deserialize().ok()?;
    let e = DeviceConfig::try_from(raw).err()?;
    Some((e.problem.key(), e.to_string()))
}

fn read(path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.to_owned(), source })
}

/// The file as a figment layer.
struct FileLayer {
    lines: Lines,
    text: String,
}

impl Provider for FileLayer {
    fn metadata(&self) -> Metadata {
        let path = self.lines.path();
        Metadata::from(path.display().to_string(), Source::File(path.to_owned()))
    }

    fn data(&self) -> Result<Map<Profile, Dict>, figment::Error> {
        let table: toml::Table = self.text.parse().map_err(|e: toml::de::Error| e.message().to_owned())?;
        figment::providers::Serialized::defaults(table).data()
    }
}

/// `--listen` and `--database` as a figment layer.
struct CliLayer(Sources);

impl Provider for CliLayer {
    fn metadata(&self) -> Metadata {
        Metadata::named("command line")
    }

    fn data(&self) -> Result<Map<Profile, Dict>, figment::Error> {
        let mut dict = Dict::new();
        if let Some(listen) = self.0.listen {
            env::insert(&mut dict, &["server", "listen"], Value::from(listen.to_string()));
        }
        if let Some(path) = &self.0.database {
            env::insert(&mut dict, &["database", "path"], Value::from(path.display().to_string()));
        }
        Ok(Profile::Default.collect(dict))
    }
}
