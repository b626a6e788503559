//! A site's tags: what a tags device's `[devices.tags]` table says (names, addresses in
//! the protocol's notation, types, word order, limits), each resolved and checked without
//! a connection ([`TagSpec`]), how a tag's value maps to bits and words ([`codec`]), and a
//! tag's latest value and quality as the device status shows it ([`TagStatus`]).
//!
//! The configuration (which checks a tags entry), the tags adapter (which polls and writes
//! the tags) and the simulators' presets (which set values the way a tag would read them)
//! use these; none of them is used here, so they do not depend on each other.

pub mod codec;
pub mod spec;
pub mod state;
pub mod table;

pub use codec::{TagType, TagValue, ValueError, WordOrder};
pub use spec::{Place, TagError, TagSpec};
pub use state::{Quality, Tag, TagFault, TagStatus};
pub use table::{TagDef, TagTable};
