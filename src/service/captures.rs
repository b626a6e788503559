//! Alarm captures (issue 42): when a device raises a `hardware` or `link` alarm, the last
//! seconds of its traffic are frozen into a pcapng file under the captures folder
//! (`retention.captures_dir`), named after the alarm, so the moment before a fault is never
//! lost to the flight recorder's ring. `GET /api/v1/alarms/{id}/capture` serves it.
//!
//! Decisions:
//! - The frames' span is fixed before the alarm is recorded (the ring moves on), the file
//!   is written once the alarm's id is known (read back from the store: the writer numbers
//!   alarms). A failure to write is logged and changes nothing else: the alarm stands.
//! - Only `hardware` and `link` classes: a `business` alarm is the crane's own decision
//!   about a load, which the job's history already tells.
//! - A file is written under another name and named once complete, so a download never
//!   reads half of one; never over a file, readable by rackd's user alone
//!   ([`crate::files`]).
//! - On the node that drives the machines, in its own folder: a standby forwards the
//!   request for an alarm's capture to the active node.
//!
//! Bounded on disk (issue 51), since the folder is usually on the disk of the database:
//! - **One capture per device and alarm** (kind and code) every
//!   `retention.alarm_capture_interval_secs` (10 minutes): a link that flaps raises its alarm
//!   again and again, and each raise would keep a minute of traffic for a week. The later
//!   raises keep none: the first shows the fault, and the events show each raise. The
//!   interval is counted on the node that drives the machines, from its start.
//! - **The folder holds at most `retention.captures_max_bytes`** (1 GiB) of captures: past
//!   it, the oldest (by the time they were written) are deleted, after each capture and at
//!   every retention pass ([`prune`]); files older than the event log's retention are
//!   deleted then too. Only rackd's own files (`alarm-*`) are counted or touched.
//! - **A temporary file a crash left** (`alarm-*.part`) is deleted once it is ten minutes
//!   old: a capture is written in well under a second, so it is no write in progress.
//! - **A file belongs to its incident**: it is named after the alarm's id and the
//!   millisecond it was raised (`alarm-ID-MS.pcapng`), and the download reads the alarm
//!   first: a database started afresh hands out alarm ids from 1 again, and its alarm 1
//!   must not be served an old incident's file. Files named `alarm-ID.pcapng` (before
//!   issue 51) are never served, and go with the retention or the cap.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime};

use tokio::time::Instant;

use crate::capture::Reader;
use crate::domain::time::to_ms;
use crate::domain::{AlarmClass, AlarmKind};
use crate::store::{Pool, alarms};

/// How old a temporary file must be before a pass takes it for a crash's leftover.
const PART_AGE: Duration = Duration::from_secs(600);

/// Where alarm captures go, how many seconds they hold, and their bounds.
#[derive(Clone, Debug)]
pub struct Freeze {
    /// The folder.
    pub folder: PathBuf,
    /// Seconds of traffic before the alarm (0: none).
    pub seconds: u64,
    /// The store, to learn the alarm's id.
    pub pool: Pool,
    /// The shortest time between two captures of one device's alarm (zero: none).
    pub every: Duration,
    /// The most bytes of captures the folder keeps.
    pub max_bytes: u64,
    /// How long a capture is kept (the event log's retention).
    pub keep: Duration,
    /// When each device's alarm last froze a capture.
    last: Arc<Mutex<HashMap<Frozen, Instant>>>,
}

/// A device's alarm: its id, the alarm's kind and code.
type Frozen = (String, AlarmKind, u16);

/// The file of the capture of alarm `id`, raised at `raised_ms` (Unix ms), in `folder`.
pub fn file_of(folder: &Path, id: i64, raised_ms: i64) -> PathBuf {
    folder.join(format!("alarm-{id}-{raised_ms}.pcapng"))
}

impl Freeze {
    /// Captures of `seconds` into `folder`, bounded as `retention` says, the alarms' ids
    /// read from `pool`; `keep` is the event log's retention.
    pub fn new(
        folder: PathBuf,
        retention: &crate::config::RetentionConfig,
        pool: Pool,
        keep: Duration,
    ) -> Freeze {
        Freeze {
            folder,
            seconds: retention.alarm_capture_seconds,
            pool,
            every: Duration::from_secs(retention.alarm_capture_interval_secs),
            max_bytes: retention.captures_max_bytes,
            keep,
            last: Arc::default(),
        }
    }

    /// Whether `device` raising alarm `key` of `class` now freezes a capture: an alarm of
    /// a class that keeps one, and none frozen for that device's alarm within the interval.
    /// Counted as frozen when it answers yes.
    pub fn admit(&self, device: &str, key: (AlarmKind, u16), class: AlarmClass) -> bool {
        if !self.wants(class) {
            return false;
        }
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let now = Instant::now();
        let id = (device.to_owned(), key.0, key.1);
        if let Some(at) = last.get(&id).filter(|at| now.duration_since(**at) < self.every) {
            tracing::info!(device, kind = %key.0, code = key.1, since_secs = now.duration_since(*at).as_secs(),
                "alarm capture: none kept, one was kept for this alarm of this device within \
                 retention.alarm_capture_interval_secs");
            return false;
        }
        last.insert(id, now);
        true
    }

    /// Writes the frames `frames` reads (its span fixed as the alarm was raised) as the
    /// capture of the active alarm `(device, kind, code)`, then keeps the folder within
    /// its bounds.
    pub async fn keep(&self, device: &str, key: (AlarmKind, u16), mut frames: Reader) {
        let active = match alarms::active(&self.pool).await {
            Ok(active) => active,
            Err(e) => return tracing::warn!(error = %e, "alarm capture: the alarm's id could not be read"),
        };
        let found = active.iter().find(|a| a.device == device && a.kind == key.0 && a.code == key.1);
        let Some(alarm) = found else { return };
        let file = file_of(&self.folder, alarm.id, to_ms(alarm.raised_at));
        let (folder, keep, max_bytes) = (self.folder.clone(), self.keep, self.max_bytes);
        let written = tokio::task::spawn_blocking(move || -> std::io::Result<(PathBuf, usize, Pruned)> {
            if let Some(dir) = file.parent() {
                std::fs::create_dir_all(dir)?;
            }
            // Written beside, then named (never over a file): a download never sees half a
            // file; the file is rackd's user's alone (`crate::files`).
            let draft = crate::files::Draft::beside(&file)?;
            let mut out = std::io::BufWriter::new(draft.file());
            let count = crate::capture::write_from(&mut frames, |bytes| out.write_all(&bytes))?;
            out.into_inner().map_err(|e| e.into_error())?;
            let file = draft.publish([file])?;
            let pruned = prune(&folder, keep, max_bytes)?;
            Ok((file, count, pruned))
        })
        .await;
        match written {
            Ok(Ok((file, count, pruned))) => {
                tracing::info!(alarm = alarm.id, frames = count, file = %file.display(), "alarm capture kept");
                pruned.log();
                if !file.exists() {
                    tracing::warn!(
                        alarm = alarm.id,
                        max_bytes,
                        "alarm capture: larger than \
                        retention.captures_max_bytes alone, so deleted at once"
                    );
                }
            }
            Ok(Err(e)) => {
                tracing::warn!(alarm = alarm.id, error = %e, "alarm capture: the file could not be written")
            }
            Err(e) => tracing::warn!(alarm = alarm.id, error = %e, "alarm capture: the write did not finish"),
        }
    }

    /// Whether an alarm of this class keeps a capture.
    pub fn wants(&self, class: AlarmClass) -> bool {
        self.seconds > 0 && matches!(class, AlarmClass::Hardware | AlarmClass::Link)
    }

    /// How far back a capture goes.
    pub fn span(&self) -> Duration {
        Duration::from_secs(self.seconds)
    }
}

/// What a pass of [`prune`] deleted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pruned {
    /// Captures older than the retention.
    pub aged: usize,
    /// Captures deleted, oldest first, to keep the folder within its bytes.
    pub over: usize,
    /// Temporary files a crash left.
    pub parts: usize,
}

impl Pruned {
    /// Logs what was deleted, if anything.
    pub fn log(&self) {
        if *self != Pruned::default() {
            tracing::info!(
                aged = self.aged,
                over_the_cap = self.over,
                leftovers = self.parts,
                "alarm captures deleted"
            );
        }
    }
}

/// Keeps the alarm captures in `folder` within their bounds: deletes those last written
/// more than `keep` ago, then the oldest until the rest is `max_bytes` at most, and
/// temporary files older than ten minutes. Only files named `alarm-*` (rackd's own, not
/// through a link) are counted or deleted; one another pass deleted first is skipped.
pub fn prune(folder: &Path, keep: Duration, max_bytes: u64) -> std::io::Result<Pruned> {
    let Ok(entries) = std::fs::read_dir(folder) else { return Ok(Pruned::default()) };
    let now = SystemTime::now();
    let mut pruned = Pruned::default();
    let mut kept = Vec::new();
    for entry in entries {
        let entry = entry?;
        let name = entry.file_name();
        let Some(name) = name.to_str().filter(|n| n.starts_with("alarm-")) else { continue };
        // Of the entry itself, not what a link names.
        let meta = match entry.metadata() {
            Ok(meta) if meta.is_file() => meta,
            Ok(_) => continue,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => return Err(e),
        };
        let written = meta.modified()?;
        let age = now.duration_since(written).unwrap_or_default();
        if name.ends_with(".part") {
            if age > PART_AGE && remove(&entry.path())? {
                pruned.parts += 1;
            }
        } else if name.ends_with(".pcapng") {
            if age > keep {
                pruned.aged += usize::from(remove(&entry.path())?);
            } else {
                kept.push((written, meta.len(), entry.path()));
            }
        }
    }
    kept.sort();
    let mut total: u64 = kept.iter().map(|(_, len, _)| len).sum();
    for (_, len, path) in kept {
        if total <= max_bytes {
            break;
        }
        pruned.over += usize::from(remove(&path)?);
        total -= len;
    }
    Ok(pruned)
}

/// Deletes `path`; false when it was gone already.
fn remove(path: &Path) -> std::io::Result<bool> {
    match std::fs::remove_file(path) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(folder: &Path, name: &str, minutes_ago: u64, size: u64) {
        let f = std::fs::File::create(folder.join(name)).unwrap();
        f.set_len(size).unwrap();
        f.set_modified(SystemTime::now() - Duration::from_secs(minutes_ago * 60)).unwrap();
    }

    fn names(folder: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(folder)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_pass_deletes_the_aged_then_the_oldest_over_the_cap_and_old_leftovers() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        file(d, "alarm-1-10.pcapng", 60 * 24 * 8, 10);
        file(d, "alarm-2-20.pcapng", 50, 400);
        file(d, "alarm-3.pcapng", 40, 400);
        file(d, "alarm-4-40.pcapng", 30, 400);
        file(d, "alarm-5-50.pcapng.part", 20, 5);
        file(d, "alarm-6-60.pcapng.part", 1, 5);
        file(d, "other.pcapng", 60 * 24 * 30, 5000);
        std::os::unix::fs::symlink(d.join("other.pcapng"), d.join("alarm-7-70.pcapng")).unwrap();
        let pruned = prune(d, Duration::from_secs(7 * 24 * 3600), 900).unwrap();
        assert_eq!(pruned, Pruned { aged: 1, over: 1, parts: 1 });
        assert_eq!(
            names(d),
            [
                "alarm-3.pcapng",
                "alarm-4-40.pcapng",
                "alarm-6-60.pcapng.part",
                "alarm-7-70.pcapng",
                "other.pcapng"
            ]
        );
        assert_eq!(prune(&d.join("none"), Duration::ZERO, 0).unwrap(), Pruned::default(), "no folder yet");
    }

    #[tokio::test(start_paused = true)]
    async fn one_capture_per_device_and_alarm_within_the_interval() {
        let pool = crate::store::Pool::Sqlite(sqlx::SqlitePool::connect_lazy("sqlite::memory:").unwrap());
        let retention =
            crate::config::RetentionConfig { alarm_capture_interval_secs: 600, ..Default::default() };
        let freeze = Freeze::new("captures".into(), &retention, pool, Duration::from_secs(3600));
        let link = (AlarmKind::Link, 0);
        assert!(freeze.admit("shelf1", link, AlarmClass::Link));
        assert!(!freeze.admit("shelf1", link, AlarmClass::Link), "the same alarm again");
        assert!(freeze.admit("shelf2", link, AlarmClass::Link), "another device");
        assert!(freeze.admit("shelf1", (AlarmKind::Device, 7011), AlarmClass::Hardware), "another alarm");
        assert!(!freeze.admit("shelf1", (AlarmKind::Heartbeat, 0), AlarmClass::Business), "a class without");
        tokio::time::advance(Duration::from_secs(600)).await;
        assert!(freeze.admit("shelf1", link, AlarmClass::Link), "after the interval");
        let every = Freeze { every: Duration::ZERO, ..freeze };
        assert!(
            every.admit("shelf1", link, AlarmClass::Link) && every.admit("shelf1", link, AlarmClass::Link)
        );
    }
}
