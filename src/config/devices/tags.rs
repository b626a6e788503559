//! `kind = "tags"`: named tags mapped to PLC addresses (see [`crate::devices::tags`]).

use std::time::Duration;

use super::defaults::{OFFLINE_AFTER, POLL_MS};
use crate::protocols::link::LinkConfig;
use crate::wire::tags::{TagDef, TagError, TagSpec, TagTable};

/// A tags device's settings, every default filled in.
#[derive(Clone, Debug, PartialEq)]
pub struct TagsConfig {
    /// The device's id.
    pub id: String,
    /// How to reach the PLC.
    pub link: LinkConfig,
    /// How often every tag is read, in milliseconds.
    pub poll_ms: u64,
    /// Consecutive failed requests after which the device is offline (writes refused).
    pub offline_after: u32,
    /// `[devices.tags]`: tag name -> address or `{ address, type, word_order, min, max,
    /// writable }`.
    pub tags: TagTable,
}

/// A tags device setting that cannot work.
#[derive(Debug, thiserror::Error)]
pub enum TagsConfigError {
    /// Nothing to poll.
    #[error("a tags device needs at least one tag in [devices.tags]")]
    NoTags,
    /// A tag does not suit the protocol.
    #[error(transparent)]
    Tag(#[from] TagError),
}

impl TagsConfig {
    /// A tags device over `link` with `tags` and every other default.
    pub fn new(id: &str, link: LinkConfig, tags: impl IntoIterator<Item = (String, TagDef)>) -> TagsConfig {
        TagsConfig {
            id: id.to_owned(),
            link,
            poll_ms: POLL_MS,
            offline_after: OFFLINE_AFTER,
            tags: TagTable(tags.into_iter().collect()),
        }
    }

    /// Poll period.
    pub fn poll(&self) -> Duration {
        Duration::from_millis(self.poll_ms.max(1))
    }

    /// Every tag resolved against the link's protocol.
    pub fn specs(&self) -> Result<Vec<TagSpec>, TagError> {
        self.tags.0.iter().map(|(name, def)| TagSpec::resolve(self.link.protocol, name, def)).collect()
    }

    /// Checks that there are tags and that each suits the protocol.
    pub fn check(&self) -> Result<(), TagsConfigError> {
        if self.tags.0.is_empty() {
            return Err(TagsConfigError::NoTags);
        }
        self.specs()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::config::devices::DeviceConfig;

    fn tags_entry(extra: &str) -> anyhow::Result<DeviceConfig> {
        let text = format!(
            "id = \"tower1\"\nkind = \"tags\"\nprotocol = \"modbus-tcp\"\naddress = \"127.0.0.1:502\"\n{extra}"
        );
        let c: DeviceConfig = toml::from_str(&text)?;
        c.check()?;
        Ok(c)
    }

    #[test]
    fn a_tags_entry_is_checked_without_a_connection() {
        let c = tags_entry(
            "[tags]\n\"beacon.red\" = \"0x1\"\nconveyor.speed = { address = \"4x100\", type = \"f32\" }\n",
        )
        .unwrap();
        let DeviceConfig::Tags(tags) = &c else { panic!("{c:?}") };
        assert_eq!((c.kind().as_str(), c.kind().job_kinds(), tags.tags.0.len()), ("tags", &[][..], 2));
        assert!(c.aisles().is_empty());
        assert_eq!((tags.poll_ms, tags.offline_after, tags.link.timeout.as_millis()), (200, 3, 300));
        let err = tags_entry("aisles = [1]\n[tags]\nx = \"0x1\"\n").unwrap_err().to_string();
        assert!(err.contains("tower1") && err.contains("aisles"), "{err}");
        let err = tags_entry("").unwrap_err().to_string();
        assert!(err.contains("at least one tag"), "{err}");
        let err = tags_entry("[tags]\nbeacon.red = \"Q0.1\"\n").unwrap_err().to_string();
        assert!(err.contains("beacon.red") && err.contains("Q0.1"), "{err}");
        let err = tags_entry("[tags]\n\"9lives\" = \"0x1\"\n").unwrap_err().to_string();
        assert!(err.contains("9lives"), "{err}");
        let err = tags_entry("[tags]\nx = { address = \"4x1\", typo = 1 }\n").unwrap_err().to_string();
        assert!(err.contains("typo"), "{err}");
    }
}
