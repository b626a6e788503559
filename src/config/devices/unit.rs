//! A `[[devices]]` entry's `unit` as written: a number (wider than any protocol's, so that
//! `unit = 300` is refused with the protocol's range rather than serde's "expected u8"), or
//! `"EE"` (any case), MEWTOCOL's global station, which rackd keeps as 238 (0xEE) and writes
//! back as `"EE"`.

use serde::{Deserialize, Serialize};

use crate::protocols::Protocol;
use crate::protocols::mewtocol::frame::GLOBAL_STATION;
use crate::protocols::protocol::Family;

/// A `unit` as written: a number, or `"EE"` (any case), MEWTOCOL's global station.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Unit {
    /// A station number as written.
    Number(i64),
    /// `"EE"`.
    Global,
}

impl Unit {
    /// How a link's unit is written back: `"EE"` for MEWTOCOL's global station.
    pub(super) fn of(protocol: Protocol, unit: u8) -> Unit {
        if protocol.family() == Family::Mewtocol && unit == GLOBAL_STATION {
            Unit::Global
        } else {
            Unit::Number(unit.into())
        }
    }
}

impl Serialize for Unit {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Unit::Number(n) => s.serialize_i64(*n),
            Unit::Global => s.serialize_str("EE"),
        }
    }
}

impl<'de> Deserialize<'de> for Unit {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Unit, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = Unit;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a station number, or \"EE\" (MEWTOCOL's global station)")
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Unit, E> {
                Ok(Unit::Number(v))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Unit, E> {
                Ok(Unit::Number(i64::try_from(v).unwrap_or(i64::MAX)))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Unit, E> {
                if v.eq_ignore_ascii_case("EE") {
                    return Ok(Unit::Global);
                }
                // A number from an environment variable arrives as text.
                v.trim()
                    .parse()
                    .map(Unit::Number)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Str(v), &self))
            }
        }
        d.deserialize_any(Visitor)
    }
}
