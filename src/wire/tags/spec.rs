//! A configured tag resolved against its device's protocol: where its value lives, its
//! type, word order, the range a write may set and whether it may be written.
//!
//! Resolution needs no connection (it uses [`notation::shape`]), so `rackd check-config`
//! refuses a bad tag the same way startup does.

use super::codec::{self, TagType, TagValue, ValueError, WordOrder, number};
use super::table::{BadTagName, TagDef, check_name};
use crate::protocols::notation::{self, Items, Shape};
use crate::protocols::protocol::Family;
use crate::protocols::{Address, PlcError, Protocol};

/// Where a tag's value lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    /// A bit address (`0x1`, `Q0.1`, `Y1A`, `M10`).
    Bit,
    /// One or two words from the address.
    Words,
    /// Bit n (0 = least significant) of the word at the address (`4x100.3`).
    WordBit(u8),
}

/// A tag ready to be read and written.
#[derive(Clone, Debug, PartialEq)]
pub struct TagSpec {
    /// The full dotted name.
    pub name: String,
    /// The address as configured.
    pub address: String,
    /// The first bit or word read.
    pub at: Address,
    /// What the address names.
    pub place: Place,
    /// The value's type.
    pub ty: TagType,
    /// Word order of 32-bit values.
    pub order: WordOrder,
    /// The smallest and largest value a write may set (numeric types): the type's range,
    /// narrowed by the area (S7 bytes: 0..=255) and the configured min/max.
    pub limits: Option<(f64, f64)>,
    /// The API may write it.
    pub writable: bool,
    /// Index distance between consecutive words of the area (2 for S7 word areas).
    pub step: u32,
    /// The area holds S7 double words, which are read in whole pairs of words.
    pub double_words: bool,
}

/// Why a tag cannot be resolved.
#[derive(Debug, thiserror::Error)]
pub enum TagError {
    /// The name is not dot-separated identifiers.
    #[error(transparent)]
    Name(#[from] BadTagName),
    /// The definition does not suit the address or protocol.
    #[error("tag {name:?}: {problem}")]
    Def {
        /// The full dotted name.
        name: String,
        /// What is wrong.
        problem: TagProblem,
    },
}

/// What is wrong with a tag's definition.
#[derive(Debug, thiserror::Error)]
pub enum TagProblem {
    /// The address does not parse in the protocol's notation.
    #[error("{0}")]
    Address(PlcError),
    /// `WORD.N` where WORD is not a 16-bit word.
    #[error("{text:?}: `ADDRESS.N` names a bit of a 16-bit word, and {word:?} is not one")]
    NotAWord {
        /// The address as configured.
        text: String,
        /// The part before the dot.
        word: String,
    },
    /// `WORD.N` with N not 0..=15.
    #[error("{0:?}: the bit after '.' must be 0..=15")]
    BitNumber(String),
    /// A non-bool type on a bit.
    #[error("{address} is a bit: it holds a bool, not {ty}")]
    BitType {
        /// The address as configured.
        address: String,
        /// The type asked for.
        ty: &'static str,
    },
    /// A non-bool type on a bit of a word.
    #[error("{address} is a bit of a word: it holds a bool, not {ty}")]
    WordBitType {
        /// The address as configured.
        address: String,
        /// The type asked for.
        ty: &'static str,
    },
    /// A bool on a whole word.
    #[error("{0} is a word: a bool needs a bit address or a bit of a word ({0}.0 .. {0}.15)")]
    BoolOnWord(String),
    /// A type other than u16 on an S7 byte.
    #[error("{address} is a byte: it holds u16 values 0..=255; use a word or double word for {ty}")]
    ByteType {
        /// The address as configured.
        address: String,
        /// The type asked for.
        ty: &'static str,
    },
    /// A 16-bit type on an S7 double word.
    #[error("{address} is a double word: it holds u32, i32 or f32, not {ty}")]
    DoubleWordType {
        /// The address as configured.
        address: String,
        /// The type asked for.
        ty: &'static str,
    },
    /// `word_order` on a type of one word.
    #[error("word_order applies to 32-bit types only, not {0}")]
    WordOrder(&'static str),
    /// The value's words run past the end of the area.
    #[error("{address}: {count} word(s) from there run past the end of the area")]
    PastEnd {
        /// The address as configured.
        address: String,
        /// Words the value takes.
        count: u16,
    },
    /// `writable = true` on an input.
    #[error("{0} is an input: the PLC refreshes it, so it cannot be writable")]
    Input(String),
    /// `min` or `max` on a bool.
    #[error("min and max apply to numeric types only")]
    LimitsNotNumeric,
    /// `min` or `max` outside the type's range (or not finite).
    #[error("{key} = {} is outside the {ty} range {}..={}", number(*value), number(*lo), number(*hi))]
    LimitOutside {
        /// `min` or `max`.
        key: &'static str,
        /// The value.
        value: f64,
        /// The tag's type.
        ty: &'static str,
        /// The range's low end.
        lo: f64,
        /// The range's high end.
        hi: f64,
    },
    /// A fractional `min` or `max` on an integer type.
    #[error("{key} = {value} must be a whole number for {ty}")]
    LimitNotWhole {
        /// `min` or `max`.
        key: &'static str,
        /// The value.
        value: f64,
        /// The tag's type.
        ty: &'static str,
    },
    /// `min` above `max`.
    #[error("min = {min} is above max = {max}")]
    MinAboveMax {
        /// The configured min.
        min: f64,
        /// The configured max.
        max: f64,
    },
}

/// Why a value could not be taken from what was read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ReadError {
    /// A bit read came back empty.
    #[error("the reply held no bit")]
    NoBit,
    /// The words do not make a value of the type.
    #[error(transparent)]
    Value(#[from] ValueError),
}

/// The order a protocol's PLCs keep 32-bit values in: Mitsubishi (MC) and Panasonic
/// (MEWTOCOL) put the low word first; Modbus convention and Siemens the high word.
pub fn native_order(protocol: Protocol) -> WordOrder {
    match protocol.family() {
        Family::Mc3e | Family::Mewtocol => WordOrder::LowFirst,
        Family::Modbus | Family::Ppi => WordOrder::HighFirst,
    }
}

/// The address's shape, and the bit of a word if the text is `WORD.N`. The protocol's own
/// notation goes first, since S7 writes bits as `V10.3`.
fn locate(protocol: Protocol, text: &str) -> Result<(Shape, Option<u8>), TagProblem> {
    let native = match notation::shape(protocol, text) {
        Ok(shape) => return Ok((shape, None)),
        Err(e) => TagProblem::Address(e),
    };
    let Some((word, bit)) = text.trim().rsplit_once('.') else { return Err(native) };
    let Ok(shape) = notation::shape(protocol, word) else { return Err(native) };
    if shape.items != Items::Words {
        return Err(TagProblem::NotAWord { text: text.to_owned(), word: word.to_owned() });
    }
    match bit.parse::<u8>() {
        Ok(n) if n <= 15 && bit.bytes().all(|b| b.is_ascii_digit()) => Ok((shape, Some(n))),
        _ => Err(TagProblem::BitNumber(text.to_owned())),
    }
}

impl TagSpec {
    /// Resolves tag `name` of a device speaking `protocol`; the error says what is wrong.
    pub fn resolve(protocol: Protocol, name: &str, def: &TagDef) -> Result<TagSpec, TagError> {
        check_name(name)?;
        Self::resolve_checked(protocol, name, def)
            .map_err(|problem| TagError::Def { name: name.to_owned(), problem })
    }

    fn resolve_checked(protocol: Protocol, name: &str, def: &TagDef) -> Result<TagSpec, TagProblem> {
        let (shape, bit) = locate(protocol, &def.address)?;
        let place = match (shape.items, bit) {
            (_, Some(b)) => Place::WordBit(b),
            (Items::Bits, None) => Place::Bit,
            _ => Place::Words,
        };
        let ty = def.ty.unwrap_or(match (shape.items, place) {
            (_, Place::Bit | Place::WordBit(_)) => TagType::Bool,
            (Items::DoubleWords, _) => TagType::U32,
            _ => TagType::U16,
        });
        let (address, t) = (|| def.address.clone(), ty.as_str());
        match (shape.items, place) {
            (_, Place::Bit) if ty != TagType::Bool => {
                return Err(TagProblem::BitType { address: address(), ty: t });
            }
            (_, Place::WordBit(_)) if ty != TagType::Bool => {
                return Err(TagProblem::WordBitType { address: address(), ty: t });
            }
            (Items::Words, Place::Words) if ty == TagType::Bool => {
                return Err(TagProblem::BoolOnWord(address()));
            }
            (Items::Bytes, _) if ty != TagType::U16 => {
                return Err(TagProblem::ByteType { address: address(), ty: t });
            }
            (Items::DoubleWords, _) if ty.words() != 2 => {
                return Err(TagProblem::DoubleWordType { address: address(), ty: t });
            }
            _ => {}
        }
        if def.word_order.is_some() && ty.words() != 2 {
            return Err(TagProblem::WordOrder(t));
        }
        let count = if place == Place::Words { ty.words() } else { 1 };
        if !shape.fits(count as u32) {
            return Err(TagProblem::PastEnd { address: address(), count });
        }
        let writable = match def.writable {
            Some(true) if !shape.writable => return Err(TagProblem::Input(address())),
            Some(w) => w,
            None => shape.writable,
        };
        Ok(TagSpec {
            name: name.to_owned(),
            address: def.address.clone(),
            at: shape.address.clone(),
            place,
            ty,
            order: def.word_order.unwrap_or_else(|| native_order(protocol)),
            limits: limits(ty, shape.items, def)?,
            writable,
            step: shape.step,
            double_words: shape.items == Items::DoubleWords,
        })
    }

    /// Bits (for [`Place::Bit`]) or words read for the value.
    pub fn count(&self) -> u16 {
        match self.place {
            Place::Words => self.ty.words(),
            Place::Bit | Place::WordBit(_) => 1,
        }
    }

    /// The value a JSON value asks for, checked against the type and [`TagSpec::limits`].
    pub fn check(&self, json: &serde_json::Value) -> Result<TagValue, ValueError> {
        let value = codec::from_json(self.ty, json)?;
        let number = match value {
            TagValue::Int(i) => i as f64,
            TagValue::Float(x) => x,
            TagValue::Bool(_) => return Ok(value),
        };
        match self.limits {
            Some((min, max)) if !(min..=max).contains(&number) => {
                Err(ValueError::Range { value: json.to_string(), min, max })
            }
            _ => Ok(value),
        }
    }

    /// The value from the bits read for a [`Place::Bit`] tag.
    pub fn from_bits(&self, bits: &[bool]) -> Result<TagValue, ReadError> {
        bits.first().map(|&b| TagValue::Bool(b)).ok_or(ReadError::NoBit)
    }

    /// The value from the words read for a word or word-bit tag.
    pub fn from_words(&self, words: &[u16]) -> Result<TagValue, ReadError> {
        match (self.place, words) {
            (Place::WordBit(bit), [word]) => Ok(TagValue::Bool(codec::bit_of(*word, bit))),
            _ => Ok(codec::decode(self.ty, self.order, words)?),
        }
    }
}

/// The range a write may set: the type's, narrowed by the area and the configured min/max,
/// which must be finite, inside the type's range, whole for integers, and in order.
fn limits(ty: TagType, items: Items, def: &TagDef) -> Result<Option<(f64, f64)>, TagProblem> {
    let Some(range) = ty.range() else {
        return match (def.min, def.max) {
            (None, None) => Ok(None),
            _ => Err(TagProblem::LimitsNotNumeric),
        };
    };
    let (lo, hi) = if items == Items::Bytes { (0.0, 255.0) } else { range };
    for (key, v) in [("min", def.min), ("max", def.max)] {
        let Some(v) = v else { continue };
        if !v.is_finite() || !(lo..=hi).contains(&v) {
            return Err(TagProblem::LimitOutside { key, value: v, ty: ty.as_str(), lo, hi });
        }
        if ty.is_integer() && v.fract() != 0.0 {
            return Err(TagProblem::LimitNotWhole { key, value: v, ty: ty.as_str() });
        }
    }
    let (min, max) = (def.min.unwrap_or(lo), def.max.unwrap_or(hi));
    if min > max {
        return Err(TagProblem::MinAboveMax { min, max });
    }
    Ok(Some((min, max)))
}

#[cfg(test)]
#[path = "spec_tests.rs"]
mod tests;
