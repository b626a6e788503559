//! The tag I/O adapter (`kind = "tags"`): named values mapped to PLC addresses over any
//! protocol (`beacon.red = "Q0.1"`, `conveyor.speed = { address = "4x100", type = "f32" }`),
//! polled at `poll_ms`, shown in the device status, and written through the API.
//!
//! Answers to the questions the issue leaves open:
//! - **Types**: bool, u16, i16, u32, i32, f32. Defaults: bool on a bit address or a bit of
//!   a word (`4x100.3`, `D200.15`, `VW10.0`: bit 0 is the least significant bit of the
//!   word's value), u16 on a word, u32 on an S7 double word (`VD`); S7 bytes (`VB`) hold u16
//!   values 0..=255. Each protocol keeps its own notation, parsed without a connection
//!   ([`crate::protocols::notation`]), so `rackd check-config` catches a bad address.
//! - **Word order** of 32-bit values: the protocol's own by default, high-first (big-endian
//!   words) for Modbus and S7, low-first for MC and MEWTOCOL, whose PLCs keep double words
//!   that way; `word_order` overrides it per tag.
//! - **Writable**: by default every tag the protocol can write; inputs (Modbus 1x/3x, S7 I
//!   and AI, MEWTOCOL X, WX and timer/counter contacts, MC X) never, since the PLC
//!   refreshes them from the field. `writable = false` protects values the PLC owns.
//! - **Writes** go through the device task, so they never interleave with a poll: the
//!   value is checked (type, the type's range, `min`/`max`, writable) before any traffic,
//!   written, read back, and the tag as read back is the answer. A bit of a word is written
//!   read-modify-write (the protocols have no atomic bit write to a word): a PLC changing
//!   another bit of that word in the same few milliseconds would lose that change, so such
//!   words should be ones rackd alone writes. An offline device refuses writes at once.
//! - **Polling**: tags that adjoin or overlap are read together (see `plan.rs`); a failed link
//!   (timeout, connection, garbled reply) ends the cycle, since the next reads would wait
//!   out the same timeout. The device's own error answer (a Modbus exception, an S7 item
//!   code) marks only that read's tags bad and still counts as contact: the PLC answered.
//! - **Status**: `tags` in the device status, name -> address, type, limits, value,
//!   quality (`unknown`, `good`, `bad`), error, `changes` and `changed_at`. A failed read
//!   keeps the last value with quality `bad`. Nothing in it changes unless a tag does.
//! - **Jobs**: none; a tags device serves no aisle and is never routed work. Pausing one
//!   changes nothing (pausing withholds new jobs): it keeps polling and taking writes.

mod handle;
mod plan;
mod poll;
mod write;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::{Instant, sleep_until};

use super::status::StatusCell;
use super::{CancelRefusal, DeviceRequest};
use crate::config::devices::TagsConfig;
use crate::protocols::{PlcError, PlcMemory};
use crate::wire::tags::{Place, TagSpec, TagStatus};

pub use handle::{TagsHandle, WriteError};
pub use plan::Group;

/// Why a tags device cannot start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// A tag's definition is wrong.
    #[error(transparent)]
    Tag(#[from] crate::wire::tags::TagError),
    /// The client does not take a tag's address.
    #[error("tag {tag:?}: {error}")]
    Address {
        /// The tag.
        tag: String,
        /// The client's answer.
        error: PlcError,
    },
    /// The client reads a tag's address otherwise than the check did.
    #[error("tag {tag:?}: {text} parses as {parsed:?}, expected {expected:?}")]
    Disagree {
        /// The tag.
        tag: String,
        /// The address as written.
        text: String,
        /// How the client reads it.
        parsed: crate::protocols::Address,
        /// How the check read it.
        expected: crate::protocols::Address,
    },
}

/// One tags device: its link, its tags and the reads that cover them.
pub struct TagDevice {
    config: TagsConfig,
    plc: Arc<dyn PlcMemory>,
    specs: Arc<Vec<TagSpec>>,
    groups: Vec<Group>,
    status: StatusCell,
    writes: mpsc::Receiver<handle::WriteRequest>,
    link_ok: bool,
}

impl TagDevice {
    /// A tags device and the handle to write its tags; nothing is sent until
    /// [`TagDevice::run`]. Fills the status with every tag, not yet read.
    pub fn new(
        config: TagsConfig,
        plc: Arc<dyn PlcMemory>,
        mut status: StatusCell,
    ) -> Result<(TagDevice, TagsHandle), StartError> {
        let specs = config.specs()?;
        for spec in &specs {
            // The client parses its own notation; it must agree with the check-time parse.
            let text = match spec.place {
                Place::WordBit(_) => spec.address.trim().rsplit_once('.').map_or("", |(word, _)| word),
                _ => spec.address.as_str(),
            };
            let parsed = plc
                .parse_address(text)
                .map_err(|error| StartError::Address { tag: spec.name.clone(), error })?;
            if parsed != spec.at {
                let (tag, expected) = (spec.name.clone(), spec.at.clone());
                return Err(StartError::Disagree { tag, text: text.to_owned(), parsed, expected });
            }
        }
        let groups = plan::plan(&specs);
        let tags = specs.iter().map(|s| (s.name.clone(), TagStatus::new(s))).collect::<BTreeMap<_, _>>();
        status.update_marked(|s| {
            s.tags = Some(tags);
            true
        });
        let (requests, writes) = mpsc::channel(16);
        let specs = Arc::new(specs);
        // Room for a poll under way, a read of a word, the write and the read-back, each
        // with every retry, and a margin.
        let deadline = request_time(&config) * (groups.len() as u32 + 3) + Duration::from_secs(1);
        let handle = TagsHandle::new(specs.clone(), status.subscribe(), requests, deadline);
        let device = TagDevice { config, plc, specs, groups, status, writes, link_ok: false };
        Ok((device, handle))
    }

    /// Runs the device until the task is aborted or asked to stop: poll at once and then
    /// every `poll_ms`, perform writes in between, refuse job requests.
    pub async fn run(mut self, mut requests: mpsc::Receiver<DeviceRequest>) {
        let period = self.config.poll();
        let mut next_poll = Instant::now();
        loop {
            tokio::select! {
                Some(write) = self.writes.recv() => self.write(write).await,
                Some(request) = requests.recv() => match request {
                    DeviceRequest::Cancel { reply, .. } => {
                        let _ = reply.send(Err(CancelRefusal::NoJobs));
                    }
                    DeviceRequest::Holding { reply, .. } => {
                        let _ = reply.send(Vec::new());
                    }
                    // A tags device holds no job: it stops between two requests.
                    DeviceRequest::Stop => return,
                },
                _ = sleep_until(next_poll) => {
                    self.poll().await;
                    next_poll = Instant::now() + period;
                }
            }
        }
    }

    /// Records the outcome of one request in the contact bookkeeping: an answer (even the
    /// device's own error code) is contact; a timeout, lost connection or garbled reply is
    /// a failure; an error raised before sending anything is neither.
    fn contact<T>(&mut self, result: &Result<T, PlcError>) {
        let outcome = match result {
            Ok(_) | Err(PlcError::Device(_)) => Ok(()),
            Err(e @ (PlcError::Timeout { .. } | PlcError::Connection(_) | PlcError::Malformed(_))) => Err(e),
            Err(PlcError::OutOfRange(_) | PlcError::BadAddress { .. }) => return,
        };
        let (offline_after, was_up) = (self.config.offline_after, self.link_ok);
        let mut up = was_up;
        let link = self.plc.link_stats();
        self.status.update(|status| {
            up = status.record_contact(outcome, offline_after, was_up, link);
            if up != status.online {
                match up {
                    true => tracing::info!("device online"),
                    false => tracing::warn!(error = ?status.last_error, "device offline"),
                }
            }
            status.online = up;
        });
        self.link_ok = up;
    }
}

/// Whether an error means the link itself failed (so the next request would fail too).
fn link_failed(e: &PlcError) -> bool {
    matches!(e, PlcError::Timeout { .. } | PlcError::Connection(_) | PlcError::Malformed(_))
}

/// How long one request may take with every retry.
fn request_time(config: &TagsConfig) -> Duration {
    config.link.timeout * (config.link.retries + 1)
}
