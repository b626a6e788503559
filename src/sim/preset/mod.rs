//! `rackd sim ... --preset FILE`: the values and read-only ranges a simulator starts with.
//!
//! A preset is JSON (or TOML when the file name ends in `.toml`):
//!
//! ```json
//! {
//!   "values": [
//!     {"address": "4x100", "type": "f32", "word_order": "cdab", "value": 3.5},
//!     {"address": "4x200", "type": "string", "length": 8, "value": "PALLET7"},
//!     {"address": "0x5", "value": true},
//!     {"address": "3x0", "values": [1, 2, 3], "read_only": true}
//!   ],
//!   "read_only": [{"address": "1x0", "count": 16}]
//! }
//! ```
//!
//! Entries use the tags' vocabulary ([`TagDef`](crate::wire::tags::TagDef):
//! addresses in the protocol's notation, `ADDRESS.N` for a bit of a word, types bool, u16,
//! i16, u32, i32, f32, `word_order`) and their codec, plus what a bench needs and a tag
//! does not:
//! - `values`: a list of values of the type at consecutive addresses, where `value` is one;
//! - `type: "string"`: ASCII, two characters a word (one per item on S7 `VB`), padded with
//!   NUL to `length` characters; the first character sits in the high byte for Modbus and S7
//!   (as pymodbus and the S7 byte order put it) and in the low byte for MC and MEWTOCOL
//!   (as GX Works shows a string in D registers);
//! - `word_order` also takes the byte-letter names `abcd` (high-first) and `cdab`
//!   (low-first) that Modbus tools use;
//! - `read_only: true` on an entry protects the items it sets; `read_only` ranges are
//!   `{address, count}` with count in items of the address (words or bits, default 1).
//!
//! Decisions where nothing else decides: two entries may not set the same item (a preset
//! means one value per item, so an overlap is a mistake) except different bits of one
//! word; read-only ranges may not overlap one another (the second one says nothing new and
//! likely meant something else); unknown keys are refused (a misspelt `word_ordr` would
//! otherwise be silently ignored). Every refusal names the file, the entry
//! (`values[2] (4x100)`) and what is wrong.

pub mod identity;
mod text;
pub mod value;

use std::path::Path;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use self::value::{Entry, Resolved};
use crate::protocols::Protocol;
use crate::sim::memory::{SimMemory, Span};

/// A read-only range: `count` items (words or bits, as the address names) from `address`.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ReadOnlyRange {
    /// The first item, in the protocol's notation.
    pub address: String,
    /// Items from there.
    #[serde(default = "one")]
    pub count: u32,
}

fn one() -> u32 {
    1
}

/// A preset file's contents.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preset {
    /// Initial values.
    #[serde(default)]
    pub values: Vec<Entry>,
    /// Ranges a master may read but not write.
    #[serde(default)]
    pub read_only: Vec<ReadOnlyRange>,
    /// What the PLC says it is (Modbus device identification, MC CPU model name).
    #[serde(default)]
    pub identity: Option<identity::Identity>,
}

impl Preset {
    /// Reads a preset file: TOML if the name ends in `.toml`, JSON otherwise.
    pub fn read(path: &Path) -> anyhow::Result<Preset> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading the preset {}", path.display()))?;
        let toml = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("toml"));
        let parsed = if toml {
            toml::from_str(&text).map_err(anyhow::Error::from)
        } else {
            serde_json::from_str(&text).map_err(anyhow::Error::from)
        };
        parsed.with_context(|| format!("{}: not a preset", path.display()))
    }

    /// Checks every entry against the simulator's memory, then writes the values and marks
    /// the ranges read-only; nothing is written unless every entry is good. Returns the
    /// read-only ranges, entries' ones included, as the control surface lists them.
    pub fn apply(
        &self,
        file: &Path,
        protocol: Protocol,
        memory: &dyn SimMemory,
    ) -> anyhow::Result<Vec<ReadOnlyRange>> {
        let file = file.display();
        let mut resolved: Vec<(String, Resolved)> = Vec::new();
        for (i, entry) in self.values.iter().enumerate() {
            let name = format!("values[{i}] ({})", entry.address);
            let r = Resolved::new(protocol, memory, entry).with_context(|| format!("{file}: {name}"))?;
            if let Some((other, _)) = resolved.iter().find(|(_, o)| o.collides(&r)) {
                anyhow::bail!("{file}: {name}: sets items {other} sets too; give each item one value");
            }
            resolved.push((name, r));
        }
        let mut ranges: Vec<(String, ReadOnlyRange, Span)> = Vec::new();
        for (name, r) in &resolved {
            if r.read_only {
                let range = ReadOnlyRange { address: r.target.address.clone(), count: r.target.items() };
                ranges.push((name.clone(), range, r.target.span.clone()));
            }
        }
        for (i, range) in self.read_only.iter().enumerate() {
            let name = format!("read_only[{i}] ({})", range.address);
            let span = range_span(protocol, memory, range).with_context(|| format!("{file}: {name}"))?;
            if let Some((other, ..)) = ranges.iter().find(|(_, _, s)| s.overlaps(&span)) {
                anyhow::bail!("{file}: {name}: overlaps {other}; read-only ranges may not overlap");
            }
            ranges.push((name, range.clone(), span));
        }
        for (name, r) in &resolved {
            r.write(memory).with_context(|| format!("{file}: {name}"))?;
        }
        for (name, range, _) in &ranges {
            let at = crate::protocols::notation::shape(protocol, &range.address)?.address;
            memory.protect(&at, range.count).with_context(|| format!("{file}: {name}"))?;
        }
        Ok(ranges.into_iter().map(|(_, range, _)| range).collect())
    }
}

/// The items a read-only range covers, checked against the memory.
pub fn range_span(protocol: Protocol, memory: &dyn SimMemory, range: &ReadOnlyRange) -> anyhow::Result<Span> {
    anyhow::ensure!(range.count > 0, "count must be at least 1");
    let shape = crate::protocols::notation::shape(protocol, &range.address)?;
    Ok(memory.span(&shape.address, range.count)?)
}

#[cfg(test)]
mod tests;
