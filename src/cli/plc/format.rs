//! How `rackd plc` shows words and reads values to write: `--format` and `--word-order`.
//!
//! The numeric formats are the tag types of the configuration (`u16`, `i16`, `u32`, `i32`,
//! `f32`, the names `[[devices.tags]]` writes) and go through the same codec
//! ([`crate::wire::tags::codec`]), so a value reads the same in `rackd plc` as in a tag.
//! Decisions of this module:
//! - **Word order** defaults to the protocol's native one, as tags do
//!   ([`native_order`](crate::wire::tags::spec::native_order)): high word first (ABCD) for Modbus and S7, low word first (CDAB) for
//!   MC and MEWTOCOL. `badc` and `dcba` also swap the two bytes of every word, for devices
//!   that store bytes little-endian inside a Modbus register; `--word-order` applies to
//!   every format, so `-f ascii --word-order badc` reads low byte first.
//! - **S7 double words** (`VD4`) are 32-bit items whatever the format: the PLC sends them
//!   high word first, so `--word-order` does not apply; `u16`/`i16`/`hex`/`bin` widen to 32
//!   bits.
//! - A float prints plain from 1e-6 to 1e15 and in exponent form beyond (`-4.9502034e32`).
//! - A float that is NaN or infinite is shown (`NaN`, `inf`; `null` in JSON), not refused
//!   as a tag's would be: commissioning is when one finds such values.
//! - `hex` shows `0x` and four digits per word; `bin` shows bytes split by `_`
//!   (`0b00010010_00110100`); both are strings in JSON. `write` takes them back, with or
//!   without the prefix.
//! - `ascii` reads all COUNT words as one string, high byte first (`HE` is 0x4845), trailing
//!   NUL bytes left out, other bytes escaped as Rust does (`\r`, `\x01`, `\"`), quoted in
//!   `ADDRESS VALUE` lines; `write -f ascii TEXT` takes one value and pads an odd length with
//!   one NUL.

use serde_json::Value as Json;

use crate::wire::tags::codec::{self, TagType, TagValue, ValueError, WordOrder};

/// How words are shown and values read (`--format` / `-f`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Unsigned 16-bit (negative values written as -32768..-1 are taken as their two's complement).
    #[default]
    U16,
    /// Signed 16-bit.
    I16,
    /// Hexadecimal, 0x1234.
    Hex,
    /// The bits of the word, 0b00010010_00110100 (bit 15 first).
    Bin,
    /// Unsigned 32-bit, two words.
    U32,
    /// Signed 32-bit, two words.
    I32,
    /// IEEE 754 32-bit float, two words.
    F32,
    /// Text, two characters per word, high byte first.
    Ascii,
}

/// Which word of a 32-bit value comes first, and whether bytes are swapped in each word
/// (`--word-order`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Order {
    /// High word first, big-endian bytes (Modbus convention, Siemens).
    #[value(alias = "big", alias = "high-first")]
    Abcd,
    /// Low word first (Mitsubishi, Panasonic, many Modbus devices).
    #[value(alias = "little", alias = "low-first")]
    Cdab,
    /// High word first, bytes swapped in each word.
    Badc,
    /// Low word first, bytes swapped in each word (fully little-endian).
    Dcba,
}

impl Order {
    /// The same order as the configuration's word order, with no byte swap.
    pub fn of(order: WordOrder) -> Order {
        match order {
            WordOrder::HighFirst => Order::Abcd,
            WordOrder::LowFirst => Order::Cdab,
        }
    }

    fn words(self) -> WordOrder {
        match self {
            Order::Abcd | Order::Badc => WordOrder::HighFirst,
            Order::Cdab | Order::Dcba => WordOrder::LowFirst,
        }
    }

    fn swaps_bytes(self) -> bool {
        matches!(self, Order::Badc | Order::Dcba)
    }
}

/// An item as shown: the text of an `ADDRESS VALUE` line and the JSON value.
#[derive(Clone, Debug, PartialEq)]
pub struct Shown {
    /// The text.
    pub text: String,
    /// The JSON value.
    pub json: Json,
}

impl Shown {
    fn number(text: String, json: impl Into<Json>) -> Shown {
        Shown { text, json: json.into() }
    }

    fn text(text: String) -> Shown {
        Shown { json: Json::String(text.clone()), text }
    }
}

/// A format applied to one kind of word item.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct View {
    /// The format.
    pub format: Format,
    /// Word order and byte swap.
    pub order: Order,
    /// Items are S7 double words: two words, high first, always 32-bit.
    pub double: bool,
}

/// What a view does with words: the format, widened to 32 bits for S7 double words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    U16,
    I16,
    Hex16,
    Bin16,
    U32,
    I32,
    Hex32,
    Bin32,
    F32,
    Ascii,
}

impl Kind {
    fn width(self) -> Option<u16> {
        match self {
            Kind::Ascii => None,
            Kind::U32 | Kind::I32 | Kind::Hex32 | Kind::Bin32 | Kind::F32 => Some(2),
            Kind::U16 | Kind::I16 | Kind::Hex16 | Kind::Bin16 => Some(1),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Kind::U16 => "u16",
            Kind::I16 => "i16",
            Kind::Hex16 | Kind::Hex32 => "hex",
            Kind::Bin16 | Kind::Bin32 => "bin",
            Kind::U32 => "u32",
            Kind::I32 => "i32",
            Kind::F32 => "f32",
            Kind::Ascii => "ascii",
        }
    }
}

impl View {
    fn kind(&self) -> Kind {
        let wide = self.double || matches!(self.format, Format::U32 | Format::I32 | Format::F32);
        match (self.format, wide) {
            (Format::U16, false) => Kind::U16,
            (Format::I16, false) => Kind::I16,
            (Format::Hex, false) => Kind::Hex16,
            (Format::Bin, false) => Kind::Bin16,
            (Format::U16 | Format::U32, _) => Kind::U32,
            (Format::I16 | Format::I32, _) => Kind::I32,
            (Format::Hex, true) => Kind::Hex32,
            (Format::Bin, true) => Kind::Bin32,
            (Format::F32, _) => Kind::F32,
            (Format::Ascii, _) => Kind::Ascii,
        }
    }

    /// Words per item: 2 for 32-bit values and double words, `None` for `ascii`, which takes
    /// every word read as one string.
    pub fn width(&self) -> Option<u16> {
        self.kind().width()
    }

    /// The format's name, as `--format` writes it (`u32` for a double word read as `u16`).
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    fn order(&self) -> Order {
        if self.double { Order::Abcd } else { self.order }
    }

    /// Words in the PLC's byte order, as the codec takes them.
    fn unswap(&self, words: &[u16]) -> Vec<u16> {
        let swap = self.order().swaps_bytes();
        words.iter().map(|w| if swap { w.swap_bytes() } else { *w }).collect()
    }

    /// The item `words` hold (one item's words; all of them for `ascii`).
    pub fn show(&self, words: &[u16]) -> Result<Shown, ValueError> {
        let kind = self.kind();
        let want = kind.width().unwrap_or(1);
        let count = || ValueError::WordCount { ty: kind.name(), got: words.len(), want };
        if words.is_empty() || kind.width().is_some_and(|w| words.len() != w as usize) {
            return Err(count());
        }
        let words = self.unswap(words);
        let order = self.order().words();
        let int = |ty| match codec::decode(ty, order, &words)? {
            TagValue::Int(v) => Ok(v),
            _ => Err(count()),
        };
        Ok(match kind {
            Kind::U16 => Shown::number(words[0].to_string(), words[0]),
            Kind::I16 => Shown::number((words[0] as i16).to_string(), words[0] as i16),
            Kind::Hex16 => Shown::text(format!("0x{:04X}", words[0])),
            Kind::Bin16 => Shown::text(binary(&words[0].to_be_bytes())),
            Kind::U32 | Kind::I32 => {
                let v = int(if kind == Kind::U32 { TagType::U32 } else { TagType::I32 })?;
                Shown::number(v.to_string(), v)
            }
            Kind::Hex32 => Shown::text(format!("0x{:08X}", int(TagType::U32)?)),
            Kind::Bin32 => Shown::text(binary(&(int(TagType::U32)? as u32).to_be_bytes())),
            Kind::F32 => match codec::decode(TagType::F32, order, &words) {
                Ok(v) => Shown::number(float_text(v), serde_json::to_value(v).unwrap_or(Json::Null)),
                Err(ValueError::NotFinite(x)) => Shown { text: x.to_string(), json: Json::Null },
                Err(e) => return Err(e),
            },
            Kind::Ascii => {
                let text = ascii(&words);
                Shown { text: format!("\"{text}\""), json: Json::String(text) }
            }
        })
    }

    /// The words of one value to write, in the format.
    pub fn parse(&self, text: &str) -> Result<Vec<u16>, String> {
        let kind = self.kind();
        let order = self.order().words();
        let bad = |expected: &str| format!("bad {} value {text:?}: expected {expected}", kind.name());
        let int = |ty: TagType| -> Result<Vec<u16>, String> {
            let (min, max) = ty.range().map(|(a, b)| (a as i64, b as i64)).unwrap_or_default();
            // Unsigned types also take the signed spelling of the same bits (-1 is 0xFFFF).
            let low = if min == 0 { -(max / 2) - 1 } else { min };
            let signed = if min == 0 { format!(" or {low}..=-1") } else { String::new() };
            let expected = format!("{min}..={max}{signed}");
            let v: i64 = text.trim().parse().map_err(|_| bad(&expected))?;
            if !(low..=max).contains(&v) {
                return Err(bad(&expected));
            }
            let value = if v < 0 && min == 0 { v + max + 1 } else { v };
            codec::encode(ty, order, TagValue::Int(value)).map_err(|e| e.to_string())
        };
        let radix = |prefix: [&str; 2], base: u32, example: &str| -> Result<Vec<u16>, String> {
            let t = text.trim();
            let digits = t.strip_prefix(prefix[0]).or_else(|| t.strip_prefix(prefix[1])).unwrap_or(t);
            let v = u32::from_str_radix(&digits.replace('_', ""), base).map_err(|_| bad(example))?;
            let too_big = || bad(&format!("{example}, at most {} bits", 16 * kind.width().unwrap_or(1)));
            match kind.width() {
                Some(2) => {
                    codec::encode(TagType::U32, order, TagValue::Int(v as i64)).map_err(|e| e.to_string())
                }
                _ => u16::try_from(v).map(|w| vec![w]).map_err(|_| too_big()),
            }
        };
        let words = match kind {
            Kind::U16 => int(TagType::U16)?,
            Kind::I16 => int(TagType::I16)?,
            Kind::U32 => int(TagType::U32)?,
            Kind::I32 => int(TagType::I32)?,
            Kind::Hex16 | Kind::Hex32 => radix(["0x", "0X"], 16, "hex digits, 0x1234")?,
            Kind::Bin16 | Kind::Bin32 => radix(["0b", "0B"], 2, "binary digits, 0b0001_0010")?,
            Kind::F32 => {
                let x: f32 = text.trim().parse().map_err(|_| bad("a number such as 3.14"))?;
                if !x.is_finite() {
                    return Err(bad("a finite number"));
                }
                codec::encode(TagType::F32, order, TagValue::Float(x as f64)).map_err(|e| e.to_string())?
            }
            Kind::Ascii if !text.is_ascii() => return Err(bad("ASCII text")),
            Kind::Ascii => text
                .as_bytes()
                .chunks(2)
                .map(|c| u16::from_be_bytes([c[0], *c.get(1).unwrap_or(&0)]))
                .collect(),
        };
        Ok(self.unswap(&words))
    }
}

/// A float as people read it: plain from 1e-6 to 1e15, in exponent form beyond (the f32's
/// shortest digits: -4.9502034e32, not 33 digits).
fn float_text(value: TagValue) -> String {
    match value {
        TagValue::Float(x) if x != 0.0 && !(1e-6..1e15).contains(&x.abs()) => format!("{:e}", x as f32),
        other => other.to_string(),
    }
}

fn binary(bytes: &[u8]) -> String {
    let parts: Vec<String> = bytes.iter().map(|b| format!("{b:08b}")).collect();
    format!("0b{}", parts.join("_"))
}

fn ascii(words: &[u16]) -> String {
    let mut bytes: Vec<u8> = words.iter().flat_map(|w| w.to_be_bytes()).collect();
    while bytes.last() == Some(&0) {
        bytes.pop();
    }
    bytes.iter().flat_map(|&b| std::ascii::escape_default(b)).map(char::from).collect()
}

#[cfg(test)]
#[path = "format_tests.rs"]
mod tests;
