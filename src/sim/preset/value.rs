//! One preset entry or control-surface request: an address, a type and values, resolved
//! against a simulator's memory and carried out there.
//!
//! Numbers and bits go through the tags' own resolution and codec ([`TagSpec`],
//! [`codec`]), so an entry means what the same tag would mean to rackd. Strings are
//! [`super::text`]'s.

use serde::{Deserialize, Serialize};
use serde_json::Value as Json;

use super::text::{text_of, text_words};
use crate::protocols::notation::{self, Items};
use crate::protocols::protocol::Family;
use crate::protocols::{Address, Protocol};
use crate::sim::memory::{SimMemory, Span};
use crate::wire::tags::spec::TagError;
use crate::wire::tags::{Place, TagDef, TagSpec, TagType, TagValue, WordOrder, codec};

/// A value's type: a tag type, or an ASCII string.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ValueType {
    /// A bit.
    Bool,
    /// Unsigned 16-bit.
    U16,
    /// Signed 16-bit.
    I16,
    /// Unsigned 32-bit.
    U32,
    /// Signed 32-bit.
    I32,
    /// IEEE 754 single precision.
    F32,
    /// ASCII text.
    String,
}

impl ValueType {
    fn tag(self) -> Option<TagType> {
        Some(match self {
            ValueType::Bool => TagType::Bool,
            ValueType::U16 => TagType::U16,
            ValueType::I16 => TagType::I16,
            ValueType::U32 => TagType::U32,
            ValueType::I32 => TagType::I32,
            ValueType::F32 => TagType::F32,
            ValueType::String => return None,
        })
    }
}

/// The word order of 32-bit values, with the byte-letter names Modbus tools use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
pub enum Order {
    /// High word first.
    #[serde(rename = "high-first", alias = "abcd", alias = "ABCD")]
    HighFirst,
    /// Low word first.
    #[serde(rename = "low-first", alias = "cdab", alias = "CDAB")]
    LowFirst,
}

/// A preset entry, and the body of `PUT /values` (the answer of `GET /values` too).
#[derive(Clone, Debug, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Entry {
    /// The first item, in the protocol's notation (`ADDRESS.N` for a bit of a word).
    pub address: String,
    /// The type [default: bool on a bit, u16 on a word, u32 on an S7 double word].
    #[serde(rename = "type", default, skip_serializing_if = "Option::is_none")]
    pub ty: Option<ValueType>,
    /// 32-bit types: `high-first` (`abcd`) or `low-first` (`cdab`) [default: the
    /// protocol's own, as for tags].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub word_order: Option<Order>,
    /// Strings: characters, the value padded with NUL to it [default: the value's].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length: Option<u16>,
    /// One value.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<Json>,
    /// Values at consecutive addresses, in place of `value`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<Json>>,
    /// Masters may not write the items set.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub read_only: bool,
}

/// How values sit in the items.
#[derive(Clone, Debug)]
enum Codec {
    Tag(Box<TagSpec>),
    /// ASCII: `per_item` characters an item (1 on S7 bytes, else 2), first in the high byte
    /// or not.
    Text {
        length: u16,
        per_item: u16,
        high_first: bool,
    },
}

/// Where `n` values of a type live in a simulator's memory, checked against it.
#[derive(Clone, Debug)]
pub struct Target {
    /// The address as given.
    pub address: String,
    at: Address,
    codec: Codec,
    n: u32,
    /// The items covered.
    pub span: Span,
}

/// Words or bits to store, checked.
#[derive(Clone, Debug)]
enum Data {
    Bits(Vec<bool>),
    Words(Vec<u16>),
    /// One bit of the word.
    Bit(u8, bool),
}

fn tag_problem(e: TagError) -> anyhow::Error {
    match e {
        TagError::Def { problem, .. } => anyhow::anyhow!("{problem}"),
        other => other.into(),
    }
}

impl Target {
    /// `n` values of `ty` from `address` (a string is one value of `length` characters).
    pub fn new(
        protocol: Protocol,
        memory: &dyn SimMemory,
        address: &str,
        ty: Option<ValueType>,
        order: Option<Order>,
        n: u32,
        length: Option<u16>,
    ) -> anyhow::Result<Target> {
        anyhow::ensure!(n > 0, "give at least one value");
        let (at, codec, items) = match ty {
            Some(ValueType::String) => {
                anyhow::ensure!(order.is_none(), "word_order applies to 32-bit types, not strings");
                anyhow::ensure!(n == 1, "a string entry takes one `value`, not `values`");
                let shape = notation::shape(protocol, address)?;
                let per_item = match shape.items {
                    Items::Words => 2,
                    Items::Bytes => 1,
                    _ => anyhow::bail!("{address} holds no words: a string needs a word or byte area"),
                };
                let length = length.ok_or_else(|| anyhow::anyhow!("a string needs its length"))?;
                anyhow::ensure!(length > 0, "length must be at least 1");
                let high_first = matches!(protocol.family(), Family::Modbus | Family::Ppi);
                let items = u32::from(length.div_ceil(per_item));
                (shape.address, Codec::Text { length, per_item, high_first }, items)
            }
            _ => {
                anyhow::ensure!(length.is_none(), "length applies to strings only");
                let def = TagDef {
                    address: address.to_owned(),
                    ty: ty.and_then(ValueType::tag),
                    word_order: order.map(|o| match o {
                        Order::HighFirst => WordOrder::HighFirst,
                        Order::LowFirst => WordOrder::LowFirst,
                    }),
                    ..TagDef::default()
                };
                let spec = TagSpec::resolve(protocol, "value", &def).map_err(tag_problem)?;
                anyhow::ensure!(
                    n == 1 || !matches!(spec.place, Place::WordBit(_)),
                    "a bit of a word takes one `value`, not `values`"
                );
                let items = n.saturating_mul(u32::from(spec.count()));
                (spec.at.clone(), Codec::Tag(Box::new(spec)), items)
            }
        };
        // Reads and writes go to the memory in one piece, counted in 16 bits.
        anyhow::ensure!(items <= u32::from(u16::MAX), "{items} items at once; at most 65535");
        let span = memory.span(&at, items)?;
        Ok(Target { address: address.to_owned(), at, codec, n, span })
    }

    /// Items (words or bits) from the address.
    pub fn items(&self) -> u32 {
        match &self.codec {
            Codec::Tag(spec) => self.n * u32::from(spec.count()),
            Codec::Text { length, per_item, .. } => u32::from(length.div_ceil(*per_item)),
        }
    }

    /// The bit of a word this names, if it does.
    fn word_bit(&self) -> Option<u8> {
        match &self.codec {
            Codec::Tag(spec) => match spec.place {
                Place::WordBit(b) => Some(b),
                _ => None,
            },
            Codec::Text { .. } => None,
        }
    }

    /// The values, checked and encoded.
    fn encode(&self, values: &[Json]) -> anyhow::Result<Data> {
        anyhow::ensure!(values.len() as u32 == self.n, "expected {} value(s), got {}", self.n, values.len());
        let spec = match &self.codec {
            Codec::Tag(spec) => spec,
            Codec::Text { length, per_item, high_first } => {
                return Ok(Data::Words(text_words(&values[0], *length, *per_item, *high_first)?));
            }
        };
        let mut bits = Vec::new();
        let mut words = Vec::new();
        for json in values {
            let value = spec.check(json)?;
            match (spec.place, value) {
                (Place::WordBit(bit), TagValue::Bool(on)) => return Ok(Data::Bit(bit, on)),
                (_, TagValue::Bool(on)) => bits.push(on),
                (_, v) => words.extend(codec::encode(spec.ty, spec.order, v)?),
            }
        }
        Ok(if spec.place == Place::Bit { Data::Bits(bits) } else { Data::Words(words) })
    }

    fn store(&self, memory: &dyn SimMemory, data: &Data) -> anyhow::Result<()> {
        match data {
            Data::Bits(bits) => memory.write_bits(&self.at, bits)?,
            Data::Words(words) => memory.write_words(&self.at, words)?,
            Data::Bit(bit, on) => {
                let word = memory.read_words(&self.at, 1)?[0];
                memory.write_words(&self.at, &[codec::with_bit(word, *bit, *on)])?;
            }
        }
        Ok(())
    }

    /// Writes values as the field does (read-only ranges do not apply).
    pub fn write(&self, memory: &dyn SimMemory, values: &[Json]) -> anyhow::Result<()> {
        self.store(memory, &self.encode(values)?)
    }

    /// Reads the values.
    pub fn read(&self, memory: &dyn SimMemory) -> anyhow::Result<Vec<Json>> {
        let items = self.items() as u16;
        let spec = match &self.codec {
            Codec::Tag(spec) => spec,
            Codec::Text { per_item, high_first, .. } => {
                let words = memory.read_words(&self.at, items)?;
                return Ok(vec![Json::String(text_of(&words, *per_item, *high_first))]);
            }
        };
        if spec.place == Place::Bit {
            return Ok(memory.read_bits(&self.at, items)?.into_iter().map(Json::Bool).collect());
        }
        let words = memory.read_words(&self.at, items)?;
        let per = spec.count() as usize;
        words
            .chunks(per)
            .map(|w| Ok(serde_json::to_value(spec.from_words(w)?)?))
            .collect::<anyhow::Result<Vec<Json>>>()
    }
}

/// A preset entry checked against the memory, ready to write.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// Where it goes.
    pub target: Target,
    data: Data,
    /// Masters may not write it.
    pub read_only: bool,
}

impl Resolved {
    /// Checks an entry: address, type, values.
    pub fn new(protocol: Protocol, memory: &dyn SimMemory, entry: &Entry) -> anyhow::Result<Resolved> {
        let values = match (&entry.value, &entry.values) {
            (Some(v), None) => vec![v.clone()],
            (None, Some(vs)) => vs.clone(),
            (None, None) => anyhow::bail!("give `value` or `values`"),
            (Some(_), Some(_)) => anyhow::bail!("give `value` or `values`, not both"),
        };
        let length = match (entry.ty, entry.length, values.first()) {
            (Some(ValueType::String), None, Some(Json::String(s))) => Some(s.len().max(1) as u16),
            (_, length, _) => length,
        };
        let target = Target::new(
            protocol,
            memory,
            &entry.address,
            entry.ty,
            entry.word_order,
            values.len() as u32,
            length,
        )?;
        anyhow::ensure!(
            !(entry.read_only && target.word_bit().is_some()),
            "read_only on a bit of a word would protect the whole word: list the word in read_only"
        );
        let data = target.encode(&values)?;
        Ok(Resolved { target, data, read_only: entry.read_only })
    }

    /// Whether two entries set the same item (different bits of one word do not).
    pub fn collides(&self, other: &Resolved) -> bool {
        match (&self.data, &other.data) {
            (Data::Bit(a, _), Data::Bit(b, _)) if a != b => false,
            _ => self.target.span.overlaps(&other.target.span),
        }
    }

    /// Writes the values as the field does.
    pub fn write(&self, memory: &dyn SimMemory) -> anyhow::Result<()> {
        self.target.store(memory, &self.data)
    }
}
