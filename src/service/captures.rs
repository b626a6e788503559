//! Alarm captures (issue 42): when a device raises a `hardware` or `link` alarm, the last
//! seconds of its traffic are frozen into a pcapng file under the captures folder
//! (`retention.captures_dir`), named after the alarm (`alarm-ID.pcapng`), so the moment
//! before a fault is never lost to the flight recorder's ring. `GET
//! /api/v1/alarms/{id}/capture` serves it; files older than the event log's retention are
//! deleted with it.
//!
//! Decisions:
//! - The frames are taken before the alarm is recorded (the ring moves on), the file is
//!   written once the alarm's id is known (read back from the store: the writer numbers
//!   alarms). A failure to write is logged and changes nothing else: the alarm stands.
//! - Only `hardware` and `link` classes: a `business` alarm is the crane's own decision
//!   about a load, which the job's history already tells.
//! - A file is written under another name and renamed once complete, so a download never
//!   reads half of one.
//! - On the node that drives the machines, in its own folder: a standby forwards the
//!   request for an alarm's capture to the active node.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use crate::capture::Reader;
use crate::domain::AlarmKind;
use crate::store::{Pool, alarms};

/// Where alarm captures go, and how many seconds they hold.
#[derive(Clone, Debug)]
pub struct Freeze {
    /// The folder.
    pub folder: PathBuf,
    /// Seconds of traffic before the alarm (0: none).
    pub seconds: u64,
    /// The store, to learn the alarm's id.
    pub pool: Pool,
}

/// The file of alarm `id`'s capture in `folder`.
pub fn file_of(folder: &Path, id: i64) -> PathBuf {
    folder.join(format!("alarm-{id}.pcapng"))
}

impl Freeze {
    /// Writes the frames `frames` reads (its span fixed as the alarm was raised) as the
    /// capture of the active alarm `(device, kind, code)`.
    pub async fn keep(&self, device: &str, key: (AlarmKind, u16), mut frames: Reader) {
        let active = match alarms::active(&self.pool).await {
            Ok(active) => active,
            Err(e) => return tracing::warn!(error = %e, "alarm capture: the alarm's id could not be read"),
        };
        let found = active.iter().find(|a| a.device == device && a.kind == key.0 && a.code == key.1);
        let Some(alarm) = found else { return };
        let file = file_of(&self.folder, alarm.id);
        let written = tokio::task::spawn_blocking(move || -> std::io::Result<(PathBuf, usize)> {
            if let Some(dir) = file.parent() {
                std::fs::create_dir_all(dir)?;
            }
            // Written beside, then renamed: a download never sees half a file.
            let part = file.with_extension("pcapng.part");
            let mut out = std::io::BufWriter::new(std::fs::File::create(&part)?);
            let count = crate::capture::write_from(&mut frames, |bytes| out.write_all(&bytes))?;
            out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
            std::fs::rename(&part, &file)?;
            Ok((file, count))
        })
        .await;
        match written {
            Ok(Ok((file, count))) => {
                tracing::info!(alarm = alarm.id, frames = count, file = %file.display(), "alarm capture kept")
            }
            Ok(Err(e)) => {
                tracing::warn!(alarm = alarm.id, error = %e, "alarm capture: the file could not be written")
            }
            Err(e) => tracing::warn!(alarm = alarm.id, error = %e, "alarm capture: the write did not finish"),
        }
    }

    /// Whether an alarm of this class keeps a capture.
    pub fn wants(&self, class: crate::domain::AlarmClass) -> bool {
        use crate::domain::AlarmClass;
        self.seconds > 0 && matches!(class, AlarmClass::Hardware | AlarmClass::Link)
    }

    /// How far back a capture goes.
    pub fn span(&self) -> Duration {
        Duration::from_secs(self.seconds)
    }
}

/// Deletes the alarm captures in `folder` last written before `keep` ago; answers how many.
pub fn prune(folder: &Path, keep: Duration) -> std::io::Result<usize> {
    let Ok(entries) = std::fs::read_dir(folder) else { return Ok(0) };
    let before = SystemTime::now().checked_sub(keep).unwrap_or(SystemTime::UNIX_EPOCH);
    let mut gone = 0;
    for entry in entries {
        let entry = entry?;
        let name = entry.file_name();
        let ours = name.to_str().is_some_and(|n| n.starts_with("alarm-") && n.ends_with(".pcapng"));
        if ours && entry.metadata()?.modified()? < before {
            std::fs::remove_file(entry.path())?;
            gone += 1;
        }
    }
    Ok(gone)
}
