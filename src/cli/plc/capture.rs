//! `rackd plc --capture FILE.pcapng`: the command's traffic with the PLC, as a pcapng file
//! Wireshark opens ([`crate::capture`]).
//!
//! Decisions:
//! - **The link's own flight recorder**, the one every device link has, with the widest
//!   bounds a link takes ([`MAX_CAPTURE_BYTES`], [`MAX_CAPTURE_SECONDS`]): a long poll keeps
//!   everything up to 256 MiB or a day, the oldest frames going first past that.
//! - **The file is created before the PLC is asked anything**, so a path that cannot be
//!   written fails at once instead of after a long poll; as a new file, never over one
//!   nor through a link there, readable by its owner alone ([`crate::files`]: a capture
//!   holds every value the PLC was sent and answered); it is filled when the command
//!   ends, whatever the outcome: after an error (the timeouts one captures for) and after
//!   Ctrl-C ([`super::run`] stops a single request on Ctrl-C too when capturing; a poll
//!   stops itself).
//! - **One link per command, so one recorder**: whoever opens the link hands its recorder to
//!   [`Capture::keep`]. A command that fails before opening a link removes the file it
//!   created and says so: no file rather than an empty one or a stale one of that name.
//! - The report goes to stderr, like the poll summary, so that `--json` output stays JSON.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::Context;

use crate::capture::{Limits, Recorder};
use crate::protocols::link::{MAX_CAPTURE_BYTES, MAX_CAPTURE_SECONDS};

/// Where the command's frames go, and the recorder that holds them until then.
pub struct Capture {
    path: PathBuf,
    file: Mutex<Option<File>>,
    recorder: Mutex<Option<Arc<Recorder>>>,
}

impl Capture {
    /// Creates `path`, a new file of rackd's own ([`crate::files::create`]), to be filled
    /// by [`Capture::finish`]; refused when anything is there.
    pub fn create(path: &Path) -> anyhow::Result<Capture> {
        let file = crate::files::create(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => anyhow::anyhow!(
                "--capture {}: a file (or a link) exists there, and rackd never writes over one: remove it \
                 or name another file",
                path.display()
            ),
            _ => anyhow::Error::new(e).context(format!("--capture {}", path.display())),
        })?;
        Ok(Capture { path: path.to_owned(), file: Mutex::new(Some(file)), recorder: Mutex::new(None) })
    }

    /// The recorder bounds for a captured link: the most a link allows.
    pub fn limits() -> Limits {
        Limits { bytes: MAX_CAPTURE_BYTES, seconds: MAX_CAPTURE_SECONDS }
    }

    /// Keeps the recorder of the link the command opened.
    pub fn keep(&self, recorder: Option<Arc<Recorder>>) {
        if let Some(recorder) = recorder {
            *self.recorder.lock().unwrap_or_else(|e| e.into_inner()) = Some(recorder);
        }
    }

    /// Writes every frame recorded to the file and says how many on stderr; the number
    /// written. Without a link (the command failed before opening one) the file is removed.
    pub fn finish(&self) -> anyhow::Result<usize> {
        let file = self.file.lock().unwrap_or_else(|e| e.into_inner()).take();
        let Some(file) = file else { return Ok(0) };
        let recorder = self.recorder.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let Some(recorder) = recorder else {
            drop(file);
            std::fs::remove_file(&self.path).with_context(|| format!("removing {}", self.path.display()))?;
            eprintln!("capture: no link was opened, nothing written to {}", self.path.display());
            return Ok(0);
        };
        let mut out = BufWriter::new(file);
        let frames = crate::capture::write_from(&mut recorder.reader(None), |part| out.write_all(&part))
            .and_then(|frames| out.flush().map(|()| frames))
            .with_context(|| format!("writing the capture to {}", self.path.display()))?;
        eprintln!("capture: {frames} frames written to {}", self.path.display());
        Ok(frames)
    }
}
