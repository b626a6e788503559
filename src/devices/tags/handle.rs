//! The rest of rackd's side of a tags device: its tags' latest values, and writes handed to
//! the device task, which performs them between two polls.
//!
//! A write is checked here (tag known, writable, value of the right type and within its
//! limits) before it reaches the task, so a bad request costs no PLC traffic. The wait for
//! the task is bounded; a write the caller stopped waiting for is dropped by the task
//! rather than performed late.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{mpsc, oneshot, watch};

use crate::devices::DeviceStatus;
use crate::protocols::PlcError;
use crate::wire::tags::Tag;
use crate::wire::tags::codec::{TagValue, ValueError};
use crate::wire::tags::spec::TagSpec;

/// A checked write on its way to the device task.
pub(super) struct WriteRequest {
    /// Index of the tag in the device's spec list.
    pub tag: usize,
    /// The value to write, already checked against the tag.
    pub value: TagValue,
    /// Where the outcome goes.
    pub reply: oneshot::Sender<Result<Tag, WriteError>>,
}

/// Why a tag write did not happen (or did not fully happen).
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// No tag of that name on this device.
    #[error("tag {0:?} is not configured on this device")]
    UnknownTag(String),
    /// The tag is configured read-only, or is an input.
    #[error("tag {0:?} is read-only")]
    ReadOnly(String),
    /// The value does not suit the tag.
    #[error("tag {tag:?}: {error}")]
    Invalid {
        /// The tag.
        tag: String,
        /// What is wrong with the value.
        error: ValueError,
    },
    /// The device is offline; nothing was sent.
    #[error("the device is offline ({0}); nothing was written")]
    Offline(String),
    /// The PLC did not take the write (nothing, or for a bit of a word nothing new, was
    /// written).
    #[error("the PLC did not take the write: {0}")]
    Plc(PlcError),
    /// The write was taken but reading the tag back failed.
    #[error("the value was written, but reading it back failed: {0}")]
    ReadBack(PlcError),
    /// The device task did not answer in time.
    #[error("the write did not finish within {0:?}; it may or may not have reached the PLC")]
    TimedOut(Duration),
    /// The device task has stopped (rackd is shutting down).
    #[error("the device task has stopped")]
    Stopped,
}

/// The handle to one tags device.
#[derive(Clone)]
pub struct TagsHandle {
    specs: Arc<Vec<TagSpec>>,
    names: Arc<BTreeMap<String, usize>>,
    status: watch::Receiver<DeviceStatus>,
    requests: mpsc::Sender<WriteRequest>,
    deadline: Duration,
}

impl TagsHandle {
    /// A handle writing through `requests`; a write waits at most `deadline` for the task.
    pub(super) fn new(
        specs: Arc<Vec<TagSpec>>,
        status: watch::Receiver<DeviceStatus>,
        requests: mpsc::Sender<WriteRequest>,
        deadline: Duration,
    ) -> Self {
        let names = specs.iter().enumerate().map(|(i, s)| (s.name.clone(), i)).collect();
        TagsHandle { specs, names: Arc::new(names), status, requests, deadline }
    }

    /// Whether the device has a tag of this name.
    pub fn has(&self, name: &str) -> bool {
        self.names.contains_key(name)
    }

    /// Every tag with its latest value, by name.
    pub fn tags(&self) -> Vec<Tag> {
        let status = self.status.borrow();
        let tags = status.tags.iter().flatten();
        tags.map(|(name, s)| Tag { name: name.clone(), status: s.clone() }).collect()
    }

    /// Checks `json` against tag `name` and has the device task write it, read it back and
    /// answer the tag as read back.
    pub async fn write(&self, name: &str, json: &serde_json::Value) -> Result<Tag, WriteError> {
        let &index = self.names.get(name).ok_or_else(|| WriteError::UnknownTag(name.to_owned()))?;
        let spec = &self.specs[index];
        if !spec.writable {
            return Err(WriteError::ReadOnly(name.to_owned()));
        }
        let value = spec.check(json).map_err(|error| WriteError::Invalid { tag: name.to_owned(), error })?;
        let (reply, answer) = oneshot::channel();
        let exchange = async {
            let request = WriteRequest { tag: index, value, reply };
            self.requests.send(request).await.map_err(|_| WriteError::Stopped)?;
            answer.await.map_err(|_| WriteError::Stopped)?
        };
        tokio::time::timeout(self.deadline, exchange)
            .await
            .map_err(|_| WriteError::TimedOut(self.deadline))?
    }
}
