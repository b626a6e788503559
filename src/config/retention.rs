//! `[retention]`: how long ended jobs stay in the store before rackd moves them to the
//! archive (`store::archive`, the same as `rackd db archive`), and where the archive is.
//!
//! Decisions:
//! - **Days, at least one** (`jobs_days`, default 90): shorter would archive jobs a WMS may
//!   still ask about the same day, and it is refused at start. There is no "off": a site
//!   that keeps everything sets a long time (36500).
//! - **The archive folder** (`archive_dir`): by default `archive` in the folder of
//!   `database.path` (`data/archive` for the default `data/rackd.db`, `/data/data/archive`
//!   in the container), with PostgreSQL too, whose server holds no files of rackd's. rackd
//!   checks at start that it can write a file there and refuses to start if not.
//! - **When**: the node that drives the machines archives at start and then every hour,
//!   the jobs that ended before midnight UTC `jobs_days` days ago. A run that fails (a full
//!   disk) deletes nothing, raises an `archive` alarm on device `store`, and is tried again
//!   at the next hour; the next run that works clears the alarm.
//! - **Alarm captures** (issue 42): when a device raises a `hardware` or `link` alarm, its
//!   last `alarm_capture_seconds` (default 60; 0: none) of traffic are frozen into
//!   `captures_dir` (by default `captures` beside the archive's default, in the folder of
//!   `database.path`), one pcapng file per alarm, kept `events.retention_hours` like the
//!   event log, and served by `GET /api/v1/alarms/{id}/capture`.
//! - **Bounded on disk** (issue 51): one capture per device and alarm (kind and code) every
//!   `alarm_capture_interval_secs` (default 600, ten minutes: a flapping link keeps the
//!   first of its raises, not one a minute; 0: every raise; at most a week), and at most
//!   `captures_max_bytes` in the folder (default 1 GiB, at least 1 MiB), the oldest
//!   deleted first (`service::captures`).

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// What an `archive` alarm asks a person to do.
pub const ARCHIVE_ACTION: &str = "Free space on the disk of retention.archive_dir (or make the folder writable \
     again); rackd deleted nothing it could not archive and tries again every hour.";

/// `[retention]`
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RetentionConfig {
    /// Days an ended job stays in the store after it ended.
    pub jobs_days: u64,
    /// Where archived jobs go (a file per day); beside the SQLite file when not set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub archive_dir: Option<PathBuf>,
    /// Where alarm captures go; `captures` beside the SQLite file when not set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub captures_dir: Option<PathBuf>,
    /// Seconds of a device's traffic frozen when it raises a `hardware` or `link` alarm
    /// (0: none).
    pub alarm_capture_seconds: u64,
    /// Seconds after a capture is frozen before the same alarm (kind and code) of the same
    /// device freezes another (0: every raise does).
    pub alarm_capture_interval_secs: u64,
    /// The most bytes of alarm captures the folder keeps; past it the oldest are deleted.
    pub captures_max_bytes: u64,
    /// How often the archive runs. Not a key of the file (hourly is right for any site);
    /// the tests shorten it.
    #[serde(skip, default = "hourly")]
    pub every: Duration,
}

fn hourly() -> Duration {
    Duration::from_secs(3600)
}

impl Default for RetentionConfig {
    fn default() -> Self {
        RetentionConfig {
            jobs_days: 90,
            archive_dir: None,
            captures_dir: None,
            alarm_capture_seconds: 60,
            alarm_capture_interval_secs: 600,
            captures_max_bytes: 1024 * 1024 * 1024,
            every: hourly(),
        }
    }
}

impl RetentionConfig {
    /// The archive folder, when `database.path` is `database_path`.
    pub fn folder(&self, database_path: &Path) -> PathBuf {
        match &self.archive_dir {
            Some(dir) => dir.clone(),
            None => database_path.parent().unwrap_or(Path::new(".")).join("archive"),
        }
    }

    /// The alarm captures' folder, when `database.path` is `database_path`.
    pub fn captures(&self, database_path: &Path) -> PathBuf {
        match &self.captures_dir {
            Some(dir) => dir.clone(),
            None => database_path.parent().unwrap_or(Path::new(".")).join("captures"),
        }
    }
}
