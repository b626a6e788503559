//! `[devices.tags]`: tag names and what each maps to, as the configuration writes them.
//!
//! A tag is `name = "ADDRESS"` (every option at its default) or
//! `name = { address = "ADDRESS", type = .., word_order = .., min = .., max = .., writable = .. }`.
//! Names are dotted (`beacon.red`). TOML reads an unquoted dotted key as nested tables, so
//! both `"beacon.red" = "Q0.1"` and `beacon.red = "Q0.1"` (or a `[devices.tags.beacon]`
//! table) name the same tag: a table with an `address` key is one tag, any other table is a
//! group whose keys continue the name. A leaf name can therefore not be one of the option
//! keys (`address`, `type`, ...).

use std::collections::BTreeMap;

use serde::{Deserialize, Deserializer, Serialize};

use super::codec::{TagType, WordOrder};

/// Longest tag name, in characters.
pub const MAX_NAME_LEN: usize = 100;

/// One tag as configured; only `address` is required.
#[derive(Clone, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TagDef {
    /// Where the value lives, in the device protocol's notation; `ADDRESS.N` (bit 0..=15)
    /// names one bit of a word (`4x100.3`, `D200.15`, `VW10.0`).
    pub address: String,
    /// The value's type; default bool on a bit (or a bit of a word), u16 on a word, u32 on
    /// an S7 double word (`VD`).
    #[serde(rename = "type")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ty: Option<TagType>,
    /// 32-bit types: which word holds the high half; default the protocol's own order
    /// (high-first for Modbus and S7, low-first for MC and MEWTOCOL).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub word_order: Option<WordOrder>,
    /// Smallest value a write may set (numeric types).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Largest value a write may set (numeric types).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    /// Whether the API may write it; default true, except on inputs, which cannot be.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub writable: Option<bool>,
}

impl TagDef {
    /// A tag at `address` with every option at its default.
    pub fn at(address: &str) -> TagDef {
        TagDef { address: address.to_owned(), ..TagDef::default() }
    }
}

/// Every tag of a device by its full dotted name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TagTable(pub BTreeMap<String, TagDef>);

impl<'de> Deserialize<'de> for TagTable {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let raw = toml::Table::deserialize(deserializer)?;
        let mut tags = BTreeMap::new();
        flatten("", raw, &mut tags).map_err(serde::de::Error::custom)?;
        Ok(TagTable(tags))
    }
}

/// A `[devices.tags]` entry that is not a tag.
#[derive(Debug, thiserror::Error)]
pub enum TagTableError {
    /// The tag's table has a wrong or unknown key.
    #[error("tag {name:?}: {source}")]
    Entry {
        /// The full dotted name.
        name: String,
        /// The parser's message.
        source: toml::de::Error,
    },
    /// Neither an address nor a table.
    #[error("tag {name:?}: expected an address string or a table, got a {got}")]
    Value {
        /// The full dotted name.
        name: String,
        /// The TOML type found.
        got: &'static str,
    },
    /// Two spellings of one name (`"a.b"` and `a.b`).
    #[error("tag {0:?} is defined twice")]
    Twice(String),
}

/// Adds the tags of `table` (whose names start with `prefix`) to `out`.
fn flatten(
    prefix: &str,
    table: toml::Table,
    out: &mut BTreeMap<String, TagDef>,
) -> Result<(), TagTableError> {
    for (key, value) in table {
        let name = if prefix.is_empty() { key } else { format!("{prefix}.{key}") };
        let def = match value {
            toml::Value::String(address) => TagDef::at(&address),
            toml::Value::Table(t) if t.contains_key("address") => match toml::Value::Table(t).try_into() {
                Ok(def) => def,
                Err(source) => return Err(TagTableError::Entry { name, source }),
            },
            toml::Value::Table(t) => {
                flatten(&name, t, out)?;
                continue;
            }
            other => return Err(TagTableError::Value { name, got: other.type_str() }),
        };
        if out.insert(name.clone(), def).is_some() {
            return Err(TagTableError::Twice(name));
        }
    }
    Ok(())
}

/// A tag name that is not dot-separated identifiers.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "tag name {0:?} must be dot-separated identifiers (letters, digits, '_'; \
     not starting with a digit), at most {MAX_NAME_LEN} characters"
)]
pub struct BadTagName(pub String);

/// Checks a tag name: dot-separated identifiers (ASCII letters, digits and `_`, not
/// starting with a digit), at most [`MAX_NAME_LEN`] characters.
pub fn check_name(name: &str) -> Result<(), BadTagName> {
    let identifier = |s: &str| {
        s.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if name.len() > MAX_NAME_LEN || !name.split('.').all(identifier) {
        return Err(BadTagName(name.to_owned()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Deserialize)]
    struct Holder {
        tags: TagTable,
    }

    fn parse(text: &str) -> Result<TagTable, toml::de::Error> {
        toml::from_str::<Holder>(text).map(|h| h.tags)
    }

    #[test]
    fn strings_tables_and_dotted_keys_make_dotted_names() {
        let tags = parse(
            r#"
            [tags]
            "beacon.red" = "Q0.1"
            beacon.green = "Q0.2"
            conveyor.speed = { address = "VD4", type = "f32", word_order = "low-first", min = 0, max = 2.5 }
            [tags.station1]
            box_present = { address = "I0.0", writable = false }
            "#,
        )
        .unwrap();
        let names: Vec<_> = tags.0.keys().map(String::as_str).collect();
        assert_eq!(names, ["beacon.green", "beacon.red", "conveyor.speed", "station1.box_present"]);
        assert_eq!(tags.0["beacon.red"], TagDef::at("Q0.1"));
        let speed = &tags.0["conveyor.speed"];
        assert_eq!((speed.ty, speed.word_order), (Some(TagType::F32), Some(WordOrder::LowFirst)));
        assert_eq!((speed.min, speed.max), (Some(0.0), Some(2.5)));
        assert_eq!(tags.0["station1.box_present"].writable, Some(false));
    }

    #[test]
    fn bad_entries_name_the_tag_and_key() {
        let err = parse("[tags]\nx = { address = \"4x1\", tpye = \"u16\" }\n").unwrap_err().to_string();
        assert!(err.contains("\"x\"") && err.contains("tpye"), "{err}");
        let err = parse("[tags]\nx = { address = \"4x1\", type = \"u64\" }\n").unwrap_err().to_string();
        assert!(err.contains("u64"), "{err}");
        let err =
            parse("[tags]\nx = { address = \"4x1\", word_order = \"middle\" }\n").unwrap_err().to_string();
        assert!(err.contains("middle"), "{err}");
        let err = parse("[tags]\nx = 5\n").unwrap_err().to_string();
        assert!(err.contains("\"x\"") && err.contains("integer"), "{err}");
        let err = parse("[tags]\n\"a.b\" = \"4x1\"\na.b = \"4x2\"\n").unwrap_err().to_string();
        assert!(err.contains("twice"), "{err}");
        // A table without an address is a group: this is tag `x.type` at address "u16",
        // which the device check then refuses as an address.
        assert!(parse("[tags]\nx = { type = \"u16\" }\n").unwrap().0.contains_key("x.type"));
    }

    #[test]
    fn names_are_dotted_identifiers() {
        for good in ["a", "beacon.red", "station1.box_present", "_x.y_2", "A.B.C"] {
            check_name(good).unwrap();
        }
        let long = "a".repeat(MAX_NAME_LEN + 1);
        for bad in ["", ".a", "a.", "a..b", "1a", "a.2b", "a-b", "a b", "a/b", "é", long.as_str()] {
            assert!(check_name(bad).is_err(), "{bad:?}");
        }
    }
}
