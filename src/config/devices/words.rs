//! The check the kinds share for an area of words rackd reads or writes (a shelf's slots, a
//! crane's register blocks): a word address of the protocol, writable where rackd writes,
//! and long enough, all without a connection.

use crate::protocols::notation::{Items, shape};
use crate::protocols::{PlcError, Protocol};

/// An area of words that does not suit what rackd does with it.
#[derive(Debug, thiserror::Error)]
pub enum WordsError {
    /// The address does not parse in the protocol's notation.
    #[error("{key} {text:?}: {source}")]
    Address {
        /// The configuration key.
        key: &'static str,
        /// Its value.
        text: String,
        /// The protocol's parse error.
        source: PlcError,
    },
    /// The address names bits, bytes or double words.
    #[error("{key} {text:?} must be a word address of {protocol}")]
    NotWords {
        /// The configuration key.
        key: &'static str,
        /// Its value.
        text: String,
        /// The link's protocol.
        protocol: Protocol,
    },
    /// rackd writes the area, and the protocol's PLC refreshes it from its inputs.
    #[error("{key} {text:?} must be a writable word address of {protocol}")]
    NotWritable {
        /// The configuration key.
        key: &'static str,
        /// Its value.
        text: String,
        /// The link's protocol.
        protocol: Protocol,
    },
    /// The area runs past the end of the PLC's memory area.
    #[error("{key} {text:?}: {count} words from there run past the end of the memory area")]
    PastEnd {
        /// The configuration key.
        key: &'static str,
        /// Its value.
        text: String,
        /// How many words rackd uses from there.
        count: u32,
    },
}

/// Checks, without a connection, that `count` words (`writable` ones when rackd writes
/// them) of `protocol` start at `text` (the value of `key`).
pub fn check_words(
    protocol: Protocol,
    key: &'static str,
    text: &str,
    count: u32,
    writable: bool,
) -> Result<(), WordsError> {
    let text_owned = || text.to_owned();
    let area =
        shape(protocol, text).map_err(|source| WordsError::Address { key, text: text_owned(), source })?;
    if area.items != Items::Words {
        return Err(WordsError::NotWords { key, text: text_owned(), protocol });
    }
    if writable && !area.writable {
        return Err(WordsError::NotWritable { key, text: text_owned(), protocol });
    }
    if !area.fits(count) {
        return Err(WordsError::PastEnd { key, text: text_owned(), count });
    }
    Ok(())
}
