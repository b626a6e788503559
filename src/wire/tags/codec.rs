//! Tag types and values, and how a value sits in 16-bit PLC words.
//!
//! 32-bit types take two consecutive words; [`WordOrder`] says which holds the high half.
//! Within a word the protocol's client already delivers the 16-bit value, so only the
//! word order varies between PLCs. Values read from a PLC and values asked for through the
//! API both pass through here: a float that is NaN or infinite is refused either way, since
//! JSON cannot carry it and no machine setting should be one.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// The type of a tag's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum TagType {
    /// A bit: a bit address, or one bit of a word (`4x100.3`).
    Bool,
    /// Unsigned 16-bit integer, one word.
    U16,
    /// Signed 16-bit integer (two's complement), one word.
    I16,
    /// Unsigned 32-bit integer, two words.
    U32,
    /// Signed 32-bit integer (two's complement), two words.
    I32,
    /// IEEE 754 single-precision float, two words.
    F32,
}

impl TagType {
    /// The type's name as the configuration writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            TagType::Bool => "bool",
            TagType::U16 => "u16",
            TagType::I16 => "i16",
            TagType::U32 => "u32",
            TagType::I32 => "i32",
            TagType::F32 => "f32",
        }
    }

    /// Words the value takes (a bool is read as the word that holds it).
    pub fn words(self) -> u16 {
        match self {
            TagType::U32 | TagType::I32 | TagType::F32 => 2,
            _ => 1,
        }
    }

    /// The smallest and largest value of a numeric type (the finite range for f32); None
    /// for bool.
    pub fn range(self) -> Option<(f64, f64)> {
        match self {
            TagType::Bool => None,
            TagType::U16 => Some((0.0, u16::MAX as f64)),
            TagType::I16 => Some((i16::MIN as f64, i16::MAX as f64)),
            TagType::U32 => Some((0.0, u32::MAX as f64)),
            TagType::I32 => Some((i32::MIN as f64, i32::MAX as f64)),
            TagType::F32 => Some((f32::MIN as f64, f32::MAX as f64)),
        }
    }

    /// Whether values are whole numbers.
    pub fn is_integer(self) -> bool {
        matches!(self, TagType::U16 | TagType::I16 | TagType::U32 | TagType::I32)
    }
}

/// Which of the two words of a 32-bit value comes first (at the lower address).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum WordOrder {
    /// High word at the lower address (big-endian words: Modbus convention, Siemens).
    HighFirst,
    /// Low word at the lower address (Mitsubishi, Panasonic, many Modbus devices).
    LowFirst,
}

impl WordOrder {
    /// The order as the configuration writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            WordOrder::HighFirst => "high-first",
            WordOrder::LowFirst => "low-first",
        }
    }
}

/// A tag's value: a bool, an integer or a float, as JSON shows it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum TagValue {
    /// A bool tag's value.
    Bool(bool),
    /// An integer tag's value.
    Int(i64),
    /// An f32 tag's value, widened to the shortest decimal that reads back as the same f32
    /// (0.1, not 0.100000001490116).
    Float(f64),
}

// The schema is written by hand: derived, an untagged enum is a `oneOf` of boolean, integer
// and number, and since JSON Schema counts 0.0 as an integer too, a float tag reading 0.0
// matched two branches and so none. A boolean or any number says the same, exactly once.
impl utoipa::PartialSchema for TagValue {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{AnyOfBuilder, ObjectBuilder, Type};
        AnyOfBuilder::new()
            .item(ObjectBuilder::new().schema_type(Type::Boolean).description(Some("A bool tag's value.")))
            .item(ObjectBuilder::new().schema_type(Type::Number).description(Some(
                "An integer tag's value, or an f32 tag's, widened to the shortest decimal that reads \
                 back as the same f32 (0.1, not 0.100000001490116).",
            )))
            .description(Some("A tag's value: a bool, an integer or a float, as JSON shows it."))
            .into()
    }
}

impl ToSchema for TagValue {}

impl std::fmt::Display for TagValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TagValue::Bool(b) => write!(f, "{b}"),
            TagValue::Int(i) => write!(f, "{i}"),
            TagValue::Float(x) => write!(f, "{x}"),
        }
    }
}

/// Why words or a requested value do not make a value of the type.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ValueError {
    /// The JSON value is of the wrong kind.
    #[error("a {ty} tag takes {expected}, not {got}")]
    Type {
        /// The tag's type.
        ty: &'static str,
        /// What it takes.
        expected: &'static str,
        /// What was given (JSON).
        got: String,
    },
    /// The value is outside the range allowed.
    #[error("{value} is out of range: the tag takes {}..={}", number(*min), number(*max))]
    Range {
        /// The value asked for (JSON).
        value: String,
        /// The smallest allowed.
        min: f64,
        /// The largest allowed.
        max: f64,
    },
    /// The PLC holds a float that is NaN or infinite.
    #[error("the PLC holds {0}, which is not a finite number")]
    NotFinite(f32),
    /// Fewer or more words than the type takes.
    #[error("{got} word(s) for a {ty} value, which takes {want}")]
    WordCount {
        /// The tag's type.
        ty: &'static str,
        /// Words given.
        got: usize,
        /// Words the type takes.
        want: u16,
    },
}

/// A limit as people read it: plain up to 15 digits, in exponent form beyond (the f32
/// range is 3.4028235e38, not 39 digits).
pub fn number(x: f64) -> String {
    match x as f32 {
        _ if x.abs() < 1e15 => x.to_string(),
        narrow if narrow as f64 == x => format!("{narrow:e}"),
        _ => format!("{x:e}"),
    }
}

/// The f32 as the shortest f64 that prints like it (f32 display is shortest round-trip).
fn widen(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(x as f64)
}

fn join(words: [u16; 2], order: WordOrder) -> u32 {
    let [first, second] = words;
    match order {
        WordOrder::HighFirst => ((first as u32) << 16) | second as u32,
        WordOrder::LowFirst => ((second as u32) << 16) | first as u32,
    }
}

fn split(value: u32, order: WordOrder) -> Vec<u16> {
    let (high, low) = ((value >> 16) as u16, value as u16);
    match order {
        WordOrder::HighFirst => vec![high, low],
        WordOrder::LowFirst => vec![low, high],
    }
}

/// The value of a numeric tag from its words (bools come from bits, see [`bit_of`]).
pub fn decode(ty: TagType, order: WordOrder, words: &[u16]) -> Result<TagValue, ValueError> {
    let count = || ValueError::WordCount { ty: ty.as_str(), got: words.len(), want: ty.words() };
    if words.len() != ty.words() as usize || ty == TagType::Bool {
        return Err(count());
    }
    let pair = || join([words[0], words[1]], order);
    Ok(match ty {
        TagType::Bool => return Err(count()),
        TagType::U16 => TagValue::Int(words[0] as i64),
        TagType::I16 => TagValue::Int(words[0] as i16 as i64),
        TagType::U32 => TagValue::Int(pair() as i64),
        TagType::I32 => TagValue::Int(pair() as i32 as i64),
        TagType::F32 => {
            let x = f32::from_bits(pair());
            if !x.is_finite() {
                return Err(ValueError::NotFinite(x));
            }
            TagValue::Float(widen(x))
        }
    })
}

/// Bit `bit` (0 = least significant) of a word.
pub fn bit_of(word: u16, bit: u8) -> bool {
    (word >> (bit & 15)) & 1 == 1
}

/// `word` with bit `bit` set to `on`.
pub fn with_bit(word: u16, bit: u8, on: bool) -> u16 {
    let mask = 1 << (bit & 15);
    if on { word | mask } else { word & !mask }
}

/// The words of a numeric value of the type; a value of another kind is refused.
pub fn encode(ty: TagType, order: WordOrder, value: TagValue) -> Result<Vec<u16>, ValueError> {
    let wrong = || ValueError::Type { ty: ty.as_str(), expected: expected(ty), got: value.to_string() };
    match (ty, value) {
        (TagType::U16 | TagType::I16, TagValue::Int(v)) => Ok(vec![v as u16]),
        (TagType::U32 | TagType::I32, TagValue::Int(v)) => Ok(split(v as u32, order)),
        (TagType::F32, TagValue::Float(v)) => Ok(split((v as f32).to_bits(), order)),
        _ => Err(wrong()),
    }
}

fn expected(ty: TagType) -> &'static str {
    match ty {
        TagType::Bool => "true or false",
        TagType::F32 => "a finite number",
        _ => "an integer",
    }
}

/// The value a JSON value stands for in a tag of the type, checked against the type's
/// range: a bool for bool, a whole number for integer types, any finite number within the
/// f32 range for f32.
pub fn from_json(ty: TagType, json: &serde_json::Value) -> Result<TagValue, ValueError> {
    let wrong = || ValueError::Type { ty: ty.as_str(), expected: expected(ty), got: json.to_string() };
    let out_of_range = |(min, max)| ValueError::Range { value: json.to_string(), min, max };
    let Some(range) = ty.range() else {
        return json.as_bool().map(TagValue::Bool).ok_or_else(wrong);
    };
    let serde_json::Value::Number(n) = json else { return Err(wrong()) };
    if ty == TagType::F32 {
        let x = n.as_f64().filter(|x| x.is_finite()).ok_or_else(wrong)?;
        // Beyond f32::MAX the cast gives infinity.
        if !(range.0..=range.1).contains(&x) {
            return Err(out_of_range(range));
        }
        return Ok(TagValue::Float(widen(x as f32)));
    }
    let v = match (n.as_i64(), n.as_u64()) {
        (Some(v), _) => v,
        (None, Some(_)) => return Err(out_of_range(range)),
        (None, None) => return Err(wrong()),
    };
    if !(range.0..=range.1).contains(&(v as f64)) {
        return Err(out_of_range(range));
    }
    Ok(TagValue::Int(v))
}

#[cfg(test)]
#[path = "codec_tests.rs"]
mod tests;
