//! Why a `[[devices]]` entry cannot be used.

use super::words::WordsError;
use super::{AddressError, CraneConfigError, DeviceKind, ShelfConfigError, TagsConfigError};
use crate::protocols::link::LinkError;
use crate::protocols::serial::SerialSettingsError;

/// A `[[devices]]` entry that cannot be used: which one, and why.
#[derive(Debug, thiserror::Error)]
#[error("devices {id:?}: {problem}")]
pub struct DeviceConfigError {
    /// The entry's `id`.
    pub id: String,
    /// What is wrong with it (boxed: a problem can carry a PLC error and a tag's name).
    pub problem: Box<Problem>,
}

impl DeviceConfigError {
    /// `problem` with entry `id`.
    pub fn new(id: &str, problem: impl Into<Problem>) -> DeviceConfigError {
        DeviceConfigError { id: id.to_owned(), problem: Box::new(problem.into()) }
    }
}

/// What is wrong with a `[[devices]]` entry.
#[derive(Debug, thiserror::Error)]
pub enum Problem {
    /// The id has characters that do not belong in a URL path or a log line.
    #[error("id must be letters, digits, '-', '_' or '.'")]
    Id,
    /// A key of another kind of device.
    #[error("`{key}` is a key of {owners} devices, not of kind = \"{kind}\"")]
    ForeignKey {
        /// The key.
        key: &'static str,
        /// The kinds it belongs to, in words (`shelf`, `shelf and crane`).
        owners: &'static str,
        /// The entry's kind.
        kind: DeviceKind,
    },
    /// `serial` does not parse.
    #[error("serial: {0}")]
    Serial(#[from] SerialSettingsError),
    /// `address`, `unit` or `serial` does not suit the protocol.
    #[error(transparent)]
    Address(#[from] AddressError),
    /// A count or time that must be above 0.
    #[error("{0} must be at least 1")]
    Zero(&'static str),
    /// The link's settings do not suit its protocol.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// A shelf setting.
    #[error(transparent)]
    Shelf(#[from] ShelfConfigError),
    /// A crane setting.
    #[error(transparent)]
    Crane(#[from] CraneConfigError),
    /// A tags device setting or tag.
    #[error(transparent)]
    Tags(#[from] TagsConfigError),
}

impl Problem {
    /// The entry's key the problem is about (`tags.beacon.red` for one tag), for
    /// pointing at its line.
    pub fn key(&self) -> String {
        use crate::wire::tags::TagError;
        let words = |e: &WordsError| match e {
            WordsError::Address { key, .. }
            | WordsError::NotWords { key, .. }
            | WordsError::NotWritable { key, .. }
            | WordsError::PastEnd { key, .. } => *key,
        };
        match self {
            Problem::Id => "id".into(),
            Problem::ForeignKey { key, .. } | Problem::Zero(key) => (*key).into(),
            Problem::Serial(_) | Problem::Address(AddressError::SerialUnused(_)) => "serial".into(),
            Problem::Address(AddressError::Unit { .. } | AddressError::GlobalStation(_))
            | Problem::Link(LinkError::Unit { .. }) => "unit".into(),
            Problem::Address(_) | Problem::Link(LinkError::Plc(_)) => "address".into(),
            Problem::Link(LinkError::Quirk { .. }) => "quirks".into(),
            Problem::Link(LinkError::Family { .. }) => "protocol".into(),
            Problem::Link(LinkError::Capture { key, .. }) => (*key).into(),
            Problem::Link(LinkError::Tuning(text)) => {
                let keys = ["degraded_window", "degraded_below", "degraded_above"];
                keys.into_iter().find(|k| text.starts_with(k)).unwrap_or("degraded_above").into()
            }
            Problem::Shelf(ShelfConfigError::NoSlots) => "slots".into(),
            Problem::Shelf(ShelfConfigError::Stride(_)) => "stride".into(),
            Problem::Shelf(ShelfConfigError::Area(e)) | Problem::Crane(CraneConfigError::Block(e)) => {
                words(e).into()
            }
            Problem::Crane(CraneConfigError::Zero(key)) => (*key).into(),
            Problem::Crane(CraneConfigError::Motion) => "motion".into(),
            Problem::Tags(TagsConfigError::NoTags) => "tags".into(),
            Problem::Tags(TagsConfigError::Tag(TagError::Name(name))) => format!("tags.{}", name.0),
            Problem::Tags(TagsConfigError::Tag(TagError::Def { name, .. })) => format!("tags.{name}"),
        }
    }
}
