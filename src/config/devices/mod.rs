//! `[[devices]]`: one entry per machine, with its protocol link and its kind's settings.
//!
//! An entry is written flat (`id`, `kind`, `protocol`, `address`, ... and the kind's own
//! keys side by side) and read into a [`DeviceConfig`] whose variant owns exactly its
//! kind's settings, with every default filled in: nothing downstream asks "if not set".
//! The flat form goes through a private struct that refuses unknown keys ([`raw`]), since
//! serde's `flatten` cannot be combined with `deny_unknown_fields`; a key of another kind
//! (`slots` on a crane, `stride` on a crane, `aisles` on a tags device) is refused by name,
//! saying which kind it belongs to.
//!
//! Reading refuses what the file cannot mean (unknown keys, values of the wrong type,
//! unknown protocols, quirks or `ack` readings, bad serial settings, a unit outside the
//! protocol's range); [`DeviceConfig::check`] then refuses values that parse but make no
//! sense (an address that is not `HOST:PORT` or a serial device as the protocol needs,
//! `serial` on a network protocol, a quirk of another protocol, a slot area the protocol
//! cannot write, a tag on an input), all without a connection, so `rackd check-config`
//! finds them. Every problem names its key ([`Problem::key`]), so that the configuration
//! can point at its line. The ranges and address forms are explained in [`address`].
//!
//! Defaults that differ by kind or protocol, and why:
//! - **Shelf quirks**: `["length0"]` over Modbus UDP, none elsewhere. The seed's PLC
//!   answers with MBAP length 0 (shelf-plc.md) and so does `rackd sim shelf` over UDP; the
//!   quirk only *tolerates* length 0 (a standard length is still accepted), so it costs a
//!   standard PLC nothing, while leaving it out makes the seed's PLC look silent.
//! - **Reply timeout**: 300 ms for shelf and tags devices (a PLC on the local network
//!   answers within a scan or two), 1500 ms for a crane: an MC 3E request waits for the
//!   end of the CPU's scan, the seed's requests give the CPU a 4 s monitoring timer, and
//!   the MC client's own default is 1.5 s. The crane's monitoring timer follows the
//!   timeout ([`crate::protocols::link`]).
//! - **Protocol**: `modbus-udp` (the seed's shelf PLC) for shelf and tags devices, `mc3e`
//!   for a crane (crane-mc3e.md), so an entry names its protocol only when it differs.
//! - **Unit**: the protocol's ([`crate::protocols::Protocol::default_unit`]); shelf slot
//!   layout: the protocol's ([`crate::wire::slot::default_layout`]).

mod address;
mod crane;
mod error;
mod raw;
mod shelf;
mod tags;
mod unit;
mod words;

use std::time::Duration;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

pub use address::{AddressError, check_address, check_serial, check_unit};
pub use crane::{Ack, CraneConfig, CraneConfigError, Planner, Station};
pub use error::{DeviceConfigError, Problem};
pub use raw::RawDevice;
pub use shelf::{ShelfConfig, ShelfConfigError, default_shelf_quirks};
pub use tags::{TagsConfig, TagsConfigError};
pub use words::{WordsError, check_words};

use crate::protocols::link::LinkConfig;

/// The kinds of machine rackd drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    /// A shelf storage PLC with task slots (shelf-plc.md).
    Shelf,
    /// A stacker crane with the MC 3E register interface (crane-mc3e.md).
    Crane,
    /// Named tags mapped to PLC addresses (light towers, stations, conveyors), polled and
    /// written through the API; runs no jobs.
    Tags,
}

impl DeviceKind {
    /// The job kinds this kind of machine runs.
    pub fn job_kinds(self) -> &'static [crate::domain::JobKind] {
        use crate::domain::JobKind::*;
        match self {
            DeviceKind::Shelf => &[Store, Retrieve, Move, Clear, Light],
            DeviceKind::Crane => &[Store, Retrieve, Move, Travel],
            DeviceKind::Tags => &[],
        }
    }

    /// The kind's name as the configuration writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            DeviceKind::Shelf => "shelf",
            DeviceKind::Crane => "crane",
            DeviceKind::Tags => "tags",
        }
    }
}

impl std::fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One `[[devices]]` entry, by kind. Every key but `id`, `kind` and `address` has a
/// default; see each kind's struct.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(try_from = "raw::RawDevice")]
pub enum DeviceConfig {
    /// `kind = "shelf"`.
    Shelf(ShelfConfig),
    /// `kind = "crane"`.
    Crane(CraneConfig),
    /// `kind = "tags"`.
    Tags(TagsConfig),
}

/// Defaults every kind shares.
pub mod defaults {
    /// How often running work (or every tag) is polled, in milliseconds.
    pub const POLL_MS: u64 = 200;
    /// Consecutive failed requests after which the device is offline.
    pub const OFFLINE_AFTER: u32 = 3;
}

impl DeviceConfig {
    /// The device's id, used in the API and in jobs' `device`.
    pub fn id(&self) -> &str {
        match self {
            DeviceConfig::Shelf(c) => &c.id,
            DeviceConfig::Crane(c) => &c.id,
            DeviceConfig::Tags(c) => &c.id,
        }
    }

    /// What kind of machine.
    pub fn kind(&self) -> DeviceKind {
        match self {
            DeviceConfig::Shelf(_) => DeviceKind::Shelf,
            DeviceConfig::Crane(_) => DeviceKind::Crane,
            DeviceConfig::Tags(_) => DeviceKind::Tags,
        }
    }

    /// The aisles whose locations the device serves (none for a tags device).
    pub fn aisles(&self) -> &[u16] {
        match self {
            DeviceConfig::Shelf(c) => &c.aisles,
            DeviceConfig::Crane(c) => &c.aisles,
            DeviceConfig::Tags(_) => &[],
        }
    }

    /// The protocol link.
    pub fn link(&self) -> &LinkConfig {
        match self {
            DeviceConfig::Shelf(c) => &c.link,
            DeviceConfig::Crane(c) => &c.link,
            DeviceConfig::Tags(c) => &c.link,
        }
    }

    /// How many of the oldest queued jobs the dispatcher weighs per round for this device
    /// (a shelf's `dispatch_window`; a crane takes one job at a time and uses the default).
    pub fn dispatch_window(&self) -> usize {
        match self {
            DeviceConfig::Shelf(c) => c.dispatch_window as usize,
            _ => shelf::DEFAULT_DISPATCH_WINDOW as usize,
        }
    }

    /// The protocol link, to change.
    pub fn link_mut(&mut self) -> &mut LinkConfig {
        match self {
            DeviceConfig::Shelf(c) => &mut c.link,
            DeviceConfig::Crane(c) => &mut c.link,
            DeviceConfig::Tags(c) => &mut c.link,
        }
    }

    /// Poll period.
    pub fn poll(&self) -> Duration {
        match self {
            DeviceConfig::Shelf(c) => c.poll(),
            DeviceConfig::Crane(c) => c.poll(),
            DeviceConfig::Tags(c) => c.poll(),
        }
    }

    /// Checks values that are valid TOML but make no sense, without a connection.
    pub fn check(&self) -> Result<(), DeviceConfigError> {
        let id = self.id();
        let fail = |problem: Problem| DeviceConfigError::new(id, problem);
        if id.is_empty() || !id.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)) {
            return Err(fail(Problem::Id));
        }
        let offline_after = match self {
            DeviceConfig::Shelf(c) => c.offline_after,
            DeviceConfig::Crane(c) => c.offline_after,
            DeviceConfig::Tags(c) => c.offline_after,
        };
        if offline_after == 0 {
            return Err(fail(Problem::Zero("offline_after")));
        }
        let link = self.link();
        check_address(link.protocol, &link.address).map_err(|e| fail(e.into()))?;
        check_unit(link.protocol, link.unit.into()).map_err(|e| fail(e.into()))?;
        check_serial(link.protocol, link.serial.is_some()).map_err(|e| fail(e.into()))?;
        link.check().map_err(|e| fail(e.into()))?;
        match self {
            DeviceConfig::Shelf(c) => c.check().map_err(|e| fail(e.into())),
            DeviceConfig::Crane(c) => c.check().map_err(|e| fail(e.into())),
            DeviceConfig::Tags(c) => c.check().map_err(|e| fail(e.into())),
        }
    }
}

impl From<ShelfConfig> for DeviceConfig {
    fn from(c: ShelfConfig) -> Self {
        DeviceConfig::Shelf(c)
    }
}

impl From<CraneConfig> for DeviceConfig {
    fn from(c: CraneConfig) -> Self {
        DeviceConfig::Crane(c)
    }
}

impl From<TagsConfig> for DeviceConfig {
    fn from(c: TagsConfig) -> Self {
        DeviceConfig::Tags(c)
    }
}

#[cfg(test)]
mod tests;
