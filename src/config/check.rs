//! Checks of a configuration that parsed: values that make no sense alone or together.
//! Each failure names the key it is about, so that the loader can say where it was set.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use super::ca::read_ca;
use super::devices::{DeviceConfigError, DeviceKind};
use super::webhooks::WebhookConfigError;
use super::{Config, EventsConfigError, Origin};
use crate::redact;
use crate::store::PgTls;

/// A configuration that parses but cannot be run.
#[derive(Debug, thiserror::Error)]
pub enum Invalid {
    /// An aisle number that is 0 or appears twice.
    #[error("site.aisles: aisle {0} is zero or listed twice")]
    AisleNumber(u16),
    /// An aisle with no locations, or more than two rows.
    #[error("site.aisles: aisle {0} needs rows 1..=2 and at least one bay, level and position")]
    AisleSize(u16),
    /// No aisles at all.
    #[error("site.aisles: at least one aisle is needed")]
    NoAisles,
    /// A depth other than 1 or 2, or double-deep where it cannot be.
    #[error(
        "site.aisles: aisle {0}: depth is 1 or 2, and 2 needs positions = 2 and no device but a crane serving the aisle"
    )]
    Depth(u16),
    /// A station number that is 0 or appears twice.
    #[error("site.stations: station {0} is zero or listed twice")]
    StationId(u16),
    /// A station's transit from an aisle the site does not have, listed twice, or not a
    /// number of seconds from 0 to a day.
    #[error(
        "site.stations: station {station}: transit from aisle {aisle} needs an aisle of site.aisles, once, and 0..=86400 seconds"
    )]
    Transit {
        /// The station.
        station: u16,
        /// The aisle.
        aisle: u16,
    },
    /// A device entry.
    #[error(transparent)]
    Device(#[from] DeviceConfigError),
    /// Two devices with one id.
    #[error("devices: id {0:?} is used twice")]
    DeviceId(String),
    /// A device serving an aisle the site does not have.
    #[error("devices {device:?}: aisle {aisle} is not in site.aisles")]
    UnknownAisle {
        /// The device.
        device: String,
        /// The aisle.
        aisle: u16,
    },
    /// Two devices serving one aisle (jobs are routed by aisle).
    #[error("devices {device:?}: aisle {aisle} is already served by {other:?}")]
    AisleServedTwice {
        /// The device.
        device: String,
        /// The aisle.
        aisle: u16,
        /// The device that serves it already.
        other: String,
    },
    /// A `database.url` that is not a PostgreSQL URL.
    #[error("{0}")]
    DatabaseUrl(String),
    /// `database.sqlite_vfs` that names nothing, or beside a PostgreSQL `database.url`.
    #[error("{0}")]
    SqliteVfs(&'static str),
    /// `[cluster]` without a PostgreSQL `database.url`, or with a bad value.
    #[error("{0}")]
    Cluster(&'static str),
    /// A TLS setting rackd cannot honour: a CA file that is not one, a CA where no mode
    /// reads it, `verify-full` without a CA.
    #[error("{0}")]
    Tls(String),
    /// `database.url_file` that cannot be read, is empty, or comes with `database.url`.
    #[error(transparent)]
    UrlFile(super::UrlFileError),
    /// A `[server]` timeout or cap of 0.
    #[error("{0} must be at least 1")]
    ServerZero(&'static str),
    /// `[server.tls]` files that cannot be served.
    #[error(transparent)]
    ServerTls(#[from] super::TlsError),
    /// An intake bound of 0.
    #[error("intake.max_group and intake.queue must be at least 1")]
    Intake,
    /// Alarm captures longer than a day.
    #[error("retention.alarm_capture_seconds: at most 86400 (0: none)")]
    AlarmCapture,
    /// An interval between alarm captures longer than a week.
    #[error("retention.alarm_capture_interval_secs: at most 604800, a week (0: a capture at every raise)")]
    AlarmCaptureInterval,
    /// A cap on the alarm captures' folder under 1 MiB.
    #[error("retention.captures_max_bytes: at least 1048576 (1 MiB)")]
    CapturesMax,
    /// A retention shorter than a day.
    #[error("retention.jobs_days must be at least 1 (there is no \"off\": keep a long time, 36500)")]
    Retention,
    /// `[events]`.
    #[error(transparent)]
    Events(#[from] EventsConfigError),
    /// A `[[webhooks]]` entry.
    #[error(transparent)]
    Webhook(#[from] WebhookConfigError),
    /// Two webhooks with one name (the name is the subscription's identity).
    #[error("webhooks: name {0:?} is used twice")]
    WebhookName(String),
    /// An `auth.keys_file` without a single key (most likely the wrong file).
    #[error("{} names no key (expected [[keys]] entries with name, role and hash)", .0.display())]
    NoKeysInFile(PathBuf),
    /// `auth.max_failures` above its bound, or a window of 0 with a limit.
    #[error("auth.max_failures is 0 (no limit) to {most}, with auth.failure_window_secs at least 1")]
    FailureLimit {
        /// The largest `max_failures`.
        most: u32,
    },
    /// Two API keys with one name or one hash.
    #[error("this key's {what} is also the {what} of the key at {first}")]
    KeyTwice {
        /// `name` or `hash`.
        what: &'static str,
        /// Where the first one is.
        first: Origin,
    },
}

/// A failed check: the key it is about, and why.
pub(super) type Flaw = (String, Invalid);

impl Config {
    /// Checks values that are valid TOML but make no sense.
    pub(super) fn check(&self) -> Result<(), Flaw> {
        let mut seen = BTreeSet::new();
        for (i, a) in self.site.aisles.iter().enumerate() {
            if a.aisle == 0 || !seen.insert(a.aisle) {
                return Err((format!("site.aisles[{i}].aisle"), Invalid::AisleNumber(a.aisle)));
            }
            let sizes =
                [("rows", a.rows), ("bays", a.bays), ("levels", a.levels), ("positions", a.positions)];
            if let Some((key, _)) = sizes.iter().find(|&&(key, n)| n == 0 || (key == "rows" && n > 2)) {
                return Err((format!("site.aisles[{i}].{key}"), Invalid::AisleSize(a.aisle)));
            }
            if !(a.depth == 1 || (a.depth == 2 && a.positions == 2)) {
                return Err((format!("site.aisles[{i}].depth"), Invalid::Depth(a.aisle)));
            }
        }
        if self.site.aisles.is_empty() {
            return Err(("site.aisles".into(), Invalid::NoAisles));
        }
        let mut stations = BTreeSet::new();
        for (i, s) in self.site.stations.iter().enumerate() {
            if s.id == 0 || !stations.insert(s.id) {
                return Err((format!("site.stations[{i}].id"), Invalid::StationId(s.id)));
            }
            let mut from = BTreeSet::new();
            for (j, t) in s.transit.iter().enumerate() {
                let ok =
                    seen.contains(&t.aisle) && from.insert(t.aisle) && (0.0..=86400.0).contains(&t.seconds);
                if !ok {
                    let key = format!("site.stations[{i}].transit[{j}]");
                    return Err((key, Invalid::Transit { station: s.id, aisle: t.aisle }));
                }
            }
        }
        let mut ids = BTreeSet::new();
        let mut served = BTreeMap::new();
        for (i, d) in self.devices.iter().enumerate() {
            let at = |key: &str| format!("devices[{i}].{key}");
            d.check().map_err(|e| (at(&e.problem.key()), e.into()))?;
            let device = d.id();
            if !ids.insert(device) {
                return Err((at("id"), Invalid::DeviceId(device.to_owned())));
            }
            for &aisle in d.aisles() {
                if !seen.contains(&aisle) {
                    return Err((at("aisles"), Invalid::UnknownAisle { device: device.to_owned(), aisle }));
                }
                if let Some(other) = served.insert(aisle, device) {
                    let (device, other) = (device.to_owned(), other.to_owned());
                    return Err((at("aisles"), Invalid::AisleServedTwice { device, aisle, other }));
                }
            }
        }
        let others: BTreeSet<u16> = self
            .devices
            .iter()
            .filter(|d| d.kind() != DeviceKind::Crane)
            .flat_map(|d| d.aisles().iter().copied())
            .collect();
        let shelf_deep =
            self.site.aisles.iter().enumerate().find(|(_, a)| a.depth == 2 && others.contains(&a.aisle));
        if let Some((i, a)) = shelf_deep {
            return Err((format!("site.aisles[{i}].depth"), Invalid::Depth(a.aisle)));
        }
        self.check_database()?;
        if let Some(c) = &self.cluster {
            let flaw = if self.database.url.is_none() {
                Some(("cluster", "a cluster shares one PostgreSQL database: set database.url"))
            } else if c.node.is_empty() || c.node.len() > 64 {
                Some(("cluster.node", "a node's name is 1 to 64 characters"))
            } else if c.url.is_none() && self.server.listen.ip().is_unspecified() {
                Some((
                    "cluster.url",
                    "server.listen is every interface: say in cluster.url where the other nodes reach this one",
                ))
            } else if c.lease_ms < 100 {
                Some(("cluster.lease_ms", "the lease is at least 100 ms"))
            } else if c.margin_ms.is_some_and(|m| m < c.lease_ms / 10 || m > c.lease_ms) {
                Some(("cluster.margin_ms", "the margin is between a tenth of the lease and the lease"))
            } else {
                None
            };
            if let Some((key, why)) = flaw {
                return Err((key.into(), Invalid::Cluster(why)));
            }
            if let Some(url) = &c.url
                && !(url.starts_with("http://") || url.starts_with("https://"))
            {
                let why = format!("{:?} is not an http:// or https:// URL", redact::url(url));
                return Err(("cluster.url".into(), Invalid::Tls(why)));
            }
            if let Some(ca) = &c.ca_file {
                read_ca(ca).map_err(|e| ("cluster.ca_file".to_owned(), Invalid::Tls(e.to_string())))?;
            }
        }
        let server = &self.server;
        let zero = [
            ("server.header_timeout_ms", server.header_timeout_ms == 0),
            ("server.idle_timeout_ms", server.idle_timeout_ms == 0),
            ("server.max_connections", server.max_connections == 0),
            ("server.capture_downloads", server.capture_downloads == 0),
        ];
        if let Some((key, _)) = zero.into_iter().find(|(_, zero)| *zero) {
            return Err((key.into(), Invalid::ServerZero(key)));
        }
        // The files as the server would load them at its start: check-config says now
        // what `serve` would refuse.
        if let Some(tls) = &server.tls {
            tls.load().map_err(|e| (e.file().key().to_owned(), Invalid::ServerTls(e)))?;
        }
        let auth = &self.auth;
        if auth.max_failures > crate::auth::MOST_FAILURES {
            return Err((
                "auth.max_failures".into(),
                Invalid::FailureLimit { most: crate::auth::MOST_FAILURES },
            ));
        }
        if auth.max_failures > 0 && auth.failure_window_secs == 0 {
            return Err((
                "auth.failure_window_secs".into(),
                Invalid::FailureLimit { most: crate::auth::MOST_FAILURES },
            ));
        }
        if self.retention.alarm_capture_seconds > 86_400 {
            return Err(("retention.alarm_capture_seconds".into(), Invalid::AlarmCapture));
        }
        if self.retention.alarm_capture_interval_secs > 604_800 {
            return Err(("retention.alarm_capture_interval_secs".into(), Invalid::AlarmCaptureInterval));
        }
        if self.retention.captures_max_bytes < 1024 * 1024 {
            return Err(("retention.captures_max_bytes".into(), Invalid::CapturesMax));
        }
        if self.retention.jobs_days == 0 {
            return Err(("retention.jobs_days".into(), Invalid::Retention));
        }
        if self.intake.max_group == 0 || self.intake.queue == 0 {
            let key = if self.intake.max_group == 0 { "intake.max_group" } else { "intake.queue" };
            return Err((key.into(), Invalid::Intake));
        }
        self.events.check().map_err(|e| {
            let ev = &self.events;
            let key = match e {
                EventsConfigError::Retention => "retention_hours",
                EventsConfigError::WebhookHold => "webhook_hold_hours",
                EventsConfigError::Zero if ev.buffer == 0 => "buffer",
                EventsConfigError::Zero if ev.ping_secs == 0 => "ping_secs",
                EventsConfigError::Zero => "send_timeout_secs",
            };
            (format!("events.{key}"), e.into())
        })?;
        self.check_webhooks()
    }
}

impl Config {
    /// `[[webhooks]]`: each entry alone (its secret and CA file read as the start reads
    /// them), then their names together.
    fn check_webhooks(&self) -> Result<(), Flaw> {
        let mut names = BTreeSet::new();
        for (i, w) in self.webhooks.iter().enumerate() {
            w.check().map_err(|e| (format!("webhooks[{i}].{}", e.problem.key(w)), e.into()))?;
            if !names.insert(w.name.as_str()) {
                return Err((format!("webhooks[{i}].name"), Invalid::WebhookName(w.name.clone())));
            }
        }
        Ok(())
    }
}

impl Config {
    /// `[database]`: the URL (printed without its password), its TLS mode, the CA files and
    /// the SQLite VFS.
    fn check_database(&self) -> Result<(), Flaw> {
        let db = &self.database;
        let vfs_flaw = |why| Err(("database.sqlite_vfs".to_owned(), Invalid::SqliteVfs(why)));
        match (db.sqlite_vfs.as_deref(), &db.url) {
            (Some(_), Some(_)) => {
                return vfs_flaw(
                    "is for the SQLite file, and database.url names a PostgreSQL server: keep one",
                );
            }
            (Some(""), None) => return vfs_flaw("names no VFS: leave it out for SQLite's default"),
            _ => {}
        }
        let url_flaw = |why: String| ("database.url".to_owned(), Invalid::DatabaseUrl(why));
        let tls_flaw = |key: &str, why: String| (key.to_owned(), Invalid::Tls(why));
        let Some(url) = &db.url else {
            return match &db.ca_file {
                Some(_) => {
                    Err(tls_flaw("database.ca_file", "is for a PostgreSQL server: set database.url".into()))
                }
                None => Ok(()),
            };
        };
        if url.starts_with("sqlite:") {
            let why = "database.url is for PostgreSQL (postgres://...); a SQLite file goes in database.path";
            return Err(url_flaw(why.into()));
        }
        if !(url.starts_with("postgres://") || url.starts_with("postgresql://")) {
            return Err(url_flaw(format!("{:?} is not a postgres:// URL", redact::url(url))));
        }
        let tls = PgTls::of(url);
        tls.check().map_err(|e| url_flaw(e.to_string()))?;
        // One host or several (libpq's `HOST1:PORT1,HOST2:PORT2`), each read by the driver.
        if let Err(e) = crate::store::hosts::Hosts::parse(url) {
            return Err(url_flaw(e.to_string()));
        }
        if let Some(root) = &tls.root_cert {
            read_ca(root).map_err(|e| url_flaw(format!("sslrootcert: {e}")))?;
        }
        if let Some(ca) = &db.ca_file {
            if tls.root_cert.is_some() {
                let why = "database.url names a CA already (sslrootcert): keep one of the two".into();
                return Err(tls_flaw("database.ca_file", why));
            }
            if let Some(mode @ ("disable" | "prefer")) = tls.mode.as_deref() {
                let why = format!(
                    "a CA is not used with sslmode={mode}: say sslmode=verify-full (or verify-ca) in database.url"
                );
                return Err(tls_flaw("database.ca_file", why));
            }
            read_ca(ca).map_err(|e| tls_flaw("database.ca_file", e.to_string()))?;
        }
        let has_ca = db.ca_file.is_some() || tls.root_cert.is_some();
        if let Some(mode @ ("verify-ca" | "verify-full")) = tls.mode.as_deref()
            && !has_ca
        {
            let why = format!(
                "sslmode={mode} needs the CA that signed the server's certificate: set database.ca_file \
                 (or sslrootcert in the URL)"
            );
            return Err(url_flaw(why));
        }
        Ok(())
    }
}
