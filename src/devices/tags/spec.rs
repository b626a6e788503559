//! A configured tag resolved against its device's protocol: where its value lives, its
//! type, word order, the range a write may set and whether it may be written.
//!
//! Resolution needs no connection (it uses [`notation::shape`]), so `rackd check-config`
//! refuses a bad tag the same way startup does.

use super::codec::{self, TagType, TagValue, ValueError, WordOrder};
use super::config::{TagDef, check_name};
use crate::protocols::Address;
use crate::protocols::notation::{self, Items, Shape};

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

/// The order a protocol's PLCs keep 32-bit values in: Mitsubishi (MC) and Panasonic
/// (MEWTOCOL) put the low word first; Modbus convention and Siemens the high word.
pub fn native_order(protocol: &str) -> WordOrder {
    if protocol.starts_with("mc3e") || protocol.starts_with("mewtocol") {
        WordOrder::LowFirst
    } else {
        WordOrder::HighFirst
    }
}

/// The address's shape, and the bit of a word if the text is `WORD.N`. The protocol's own
/// notation goes first, since S7 writes bits as `V10.3`.
fn locate(protocol: &str, text: &str) -> Result<(Shape, Option<u8>), String> {
    let native = match notation::shape(protocol, text) {
        Ok(shape) => return Ok((shape, None)),
        Err(e) => e.to_string(),
    };
    let Some((word, bit)) = text.trim().rsplit_once('.') else { return Err(native) };
    let Ok(shape) = notation::shape(protocol, word) else { return Err(native) };
    if shape.items != Items::Words {
        return Err(format!("{text:?}: `ADDRESS.N` names a bit of a 16-bit word, and {word:?} is not one"));
    }
    match bit.parse::<u8>() {
        Ok(n) if n <= 15 && bit.bytes().all(|b| b.is_ascii_digit()) => Ok((shape, Some(n))),
        _ => Err(format!("{text:?}: the bit after '.' must be 0..=15")),
    }
}

impl TagSpec {
    /// Resolves tag `name` of a device speaking `protocol`; the error says what is wrong.
    pub fn resolve(protocol: &str, name: &str, def: &TagDef) -> Result<TagSpec, String> {
        check_name(name)?;
        Self::resolve_checked(protocol, name, def).map_err(|e| format!("tag {name:?}: {e}"))
    }

    fn resolve_checked(protocol: &str, name: &str, def: &TagDef) -> Result<TagSpec, String> {
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
        let (a, t) = (&def.address, ty.as_str());
        match (shape.items, place) {
            (_, Place::Bit) if ty != TagType::Bool => {
                return Err(format!("{a} is a bit: it holds a bool, not {t}"));
            }
            (_, Place::WordBit(_)) if ty != TagType::Bool => {
                return Err(format!("{a} is a bit of a word: it holds a bool, not {t}"));
            }
            (Items::Words, Place::Words) if ty == TagType::Bool => {
                return Err(format!(
                    "{a} is a word: a bool needs a bit address or a bit of a word ({a}.0 .. {a}.15)"
                ));
            }
            (Items::Bytes, _) if ty != TagType::U16 => {
                return Err(format!(
                    "{a} is a byte: it holds u16 values 0..=255; use a word or double word for {t}"
                ));
            }
            (Items::DoubleWords, _) if ty.words() != 2 => {
                return Err(format!("{a} is a double word: it holds u32, i32 or f32, not {t}"));
            }
            _ => {}
        }
        if def.word_order.is_some() && ty.words() != 2 {
            return Err(format!("word_order applies to 32-bit types only, not {t}"));
        }
        let count = if place == Place::Words { ty.words() } else { 1 };
        if !shape.fits(count as u32) {
            return Err(format!("{a}: {count} word(s) from there run past the end of the area"));
        }
        let writable = match def.writable {
            Some(true) if !shape.writable => {
                return Err(format!("{a} is an input: the PLC refreshes it, so it cannot be writable"));
            }
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
    pub fn from_bits(&self, bits: &[bool]) -> Result<TagValue, String> {
        bits.first().map(|&b| TagValue::Bool(b)).ok_or_else(|| "the reply held no bit".to_owned())
    }

    /// The value from the words read for a word or word-bit tag.
    pub fn from_words(&self, words: &[u16]) -> Result<TagValue, String> {
        match (self.place, words) {
            (Place::WordBit(bit), [word]) => Ok(TagValue::Bool(codec::bit_of(*word, bit))),
            _ => codec::decode(self.ty, self.order, words).map_err(|e| e.to_string()),
        }
    }
}

/// The range a write may set: the type's, narrowed by the area and the configured min/max,
/// which must be finite, inside the type's range, whole for integers, and in order.
fn limits(ty: TagType, items: Items, def: &TagDef) -> Result<Option<(f64, f64)>, String> {
    let Some(range) = ty.range() else {
        return match (def.min, def.max) {
            (None, None) => Ok(None),
            _ => Err("min and max apply to numeric types only".into()),
        };
    };
    let (lo, hi) = if items == Items::Bytes { (0.0, 255.0) } else { range };
    for (key, v) in [("min", def.min), ("max", def.max)] {
        let Some(v) = v else { continue };
        if !v.is_finite() || !(lo..=hi).contains(&v) {
            let (v, lo, hi) = (codec::number(v), codec::number(lo), codec::number(hi));
            return Err(format!("{key} = {v} is outside the {} range {lo}..={hi}", ty.as_str()));
        }
        if ty.is_integer() && v.fract() != 0.0 {
            return Err(format!("{key} = {v} must be a whole number for {}", ty.as_str()));
        }
    }
    let (min, max) = (def.min.unwrap_or(lo), def.max.unwrap_or(hi));
    if min > max {
        return Err(format!("min = {min} is above max = {max}"));
    }
    Ok(Some((min, max)))
}

#[cfg(test)]
#[path = "spec_tests.rs"]
mod tests;
