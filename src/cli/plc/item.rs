//! What an address holds for `rackd plc`, and how its items are read, written and named.
//!
//! An address is parsed before connecting with the notation the clients use
//! ([`notation::shape`]), so a typo or a write to an input fails at once, without a
//! timeout. An item is what one `ADDRESS VALUE` line shows: a bit, a word, two words for a
//! 32-bit format, an S7 double word (`VD4`, always 32 bits), or for `ascii` all the words
//! read. Its label is the address of its first word in the protocol's notation
//! (`read VD4 2` prints VD4 and VD8; `read 4x100 2 -f f32` prints 4x100 and 4x102), and
//! Modbus addresses are printed in the area notation whichever notation was typed.

use anyhow::{Context, anyhow, bail};

use super::format::{Format, Order, Shown, View};
use super::hints;

use crate::protocols::notation::{self, Items, Shape};
use crate::protocols::protocol::Family;
use crate::protocols::{Address, PlcMemory, Protocol, mc3e, mewtocol, modbus, ppi};

/// One line of output: the item's address and its value.
pub type Item = (String, Shown);

/// A parsed address and how its items are shown.
#[derive(Clone, Debug)]
pub struct Target {
    protocol: Protocol,
    text: String,
    shape: Shape,
    /// None for bits.
    view: Option<View>,
}

impl Target {
    /// `text` in the protocol's notation, with the display format; refuses a format the
    /// area cannot hold (a word format on bits, a 32-bit one on S7 bytes).
    pub fn new(
        protocol: Protocol,
        text: &str,
        format: Option<Format>,
        order: Order,
    ) -> anyhow::Result<Target> {
        let shape = notation::shape(protocol, text).map_err(|e| anyhow!(hints::explain(&e, protocol)))?;
        let chosen = format.unwrap_or_default();
        let view = match shape.items {
            Items::Bits if format.is_some_and(|f| f != Format::U16) => {
                bail!(
                    "{text} names bits, read as 0 and 1: --format applies to words{}",
                    bits_note(protocol, text)
                )
            }
            Items::Bits => None,
            Items::Bytes if !matches!(chosen, Format::U16 | Format::I16 | Format::Hex | Format::Bin) => {
                bail!(
                    "{text} names bytes: read 32-bit values from a double word (VD) and text from words (VW)"
                )
            }
            Items::DoubleWords if chosen == Format::Ascii => {
                bail!("{text} names double words: read text from words (VW)")
            }
            Items::DoubleWords => Some(View { format: chosen, order, double: true }),
            _ => Some(View { format: chosen, order, double: false }),
        };
        Ok(Target { protocol, text: text.to_owned(), shape, view })
    }

    /// Words (or bits) to ask for to get `count` items.
    fn size(&self, count: u16) -> anyhow::Result<u16> {
        let width = self.view.map_or(Some(1), |v| v.width()).unwrap_or(1);
        let size = count.checked_mul(width).filter(|&n| n > 0).context("COUNT must be 1..65535 words")?;
        let last = self.shape.step.checked_mul(size as u32).context("COUNT is too large")?;
        if self.shape.address.index as u64 + last as u64 > self.shape.limit {
            bail!("{} from {} runs past the end of the area", plural(count), self.text);
        }
        Ok(size)
    }

    /// The label of the item `words` words after the start.
    fn label(&self, words: u32) -> String {
        let at = self.shape.address.offset(words * self.shape.step);
        format_address(self.protocol, &at)
    }

    fn items(&self, words: &[u16]) -> anyhow::Result<Vec<Item>> {
        let view = self.view.context("a bit area has no words")?;
        let width = view.width().map_or(words.len().max(1), usize::from);
        let mut items = Vec::new();
        for (i, chunk) in words.chunks(width).enumerate() {
            let shown = view.show(chunk).map_err(|e| anyhow!("{}: {e}", self.label((i * width) as u32)))?;
            items.push((self.label((i * width) as u32), shown));
        }
        Ok(items)
    }

    /// Reads `count` items.
    pub async fn read(&self, plc: &dyn PlcMemory, count: u16) -> anyhow::Result<Vec<Item>> {
        let size = self.size(count)?;
        let start = &self.shape.address;
        let failed = |e| anyhow!(hints::explain(&e, self.protocol));
        if self.view.is_none() {
            let bits = plc.read_bits(start, size).await.map_err(failed)?;
            return Ok(bits.into_iter().enumerate().map(|(i, b)| (self.label(i as u32), bit(b))).collect());
        }
        let words = plc.read_words(start, size).await.map_err(failed)?;
        self.items(&words)
    }

    /// Writes the values, each in the display format; returns the items written.
    pub async fn write(&self, plc: &dyn PlcMemory, values: &[String]) -> anyhow::Result<Vec<Item>> {
        if !self.shape.writable {
            bail!("{} is an input the PLC refreshes from the field: it cannot be written", self.text);
        }
        let start = &self.shape.address;
        let failed = |e| anyhow!(hints::explain(&e, self.protocol));
        let Some(view) = self.view else {
            let bits = values
                .iter()
                .map(|v| parse_bit(v, self.protocol, &self.text))
                .collect::<Result<Vec<_>, _>>()?;
            plc.write_bits(start, &bits).await.map_err(failed)?;
            return Ok(bits.into_iter().enumerate().map(|(i, b)| (self.label(i as u32), bit(b))).collect());
        };
        if view.format == Format::Ascii && values.len() != 1 {
            bail!("-f ascii writes one text; quote it if it holds spaces");
        }
        let mut words = Vec::new();
        for value in values {
            words.extend(view.parse(value).map_err(|e| anyhow!(e))?);
        }
        let count = u16::try_from(words.len()).context("too many values")?;
        self.size(view.width().map_or(count, |w| count / w))?;
        plc.write_words(start, &words).await.map_err(failed)?;
        self.items(&words)
    }
}

fn plural(count: u16) -> String {
    if count == 1 { "1 item".into() } else { format!("{count} items") }
}

fn bit(on: bool) -> Shown {
    Shown { text: u8::from(on).to_string(), json: u8::from(on).into() }
}

fn parse_bit(text: &str, protocol: Protocol, address: &str) -> anyhow::Result<bool> {
    match text.to_ascii_lowercase().as_str() {
        "1" | "true" | "on" => Ok(true),
        "0" | "false" | "off" => Ok(false),
        _ => bail!(
            "bad bit value {text:?}: {address} names bits, written as 0 or 1{}",
            bits_note(protocol, address)
        ),
    }
}

/// For a Modbus `0x` address read as words: what the notation means, since `0x10` looks
/// like hex sixteen.
fn bits_note(protocol: Protocol, text: &str) -> String {
    let Ok(address) = modbus::address::parse(text) else { return String::new() };
    let digits =
        text.trim().get(2..).filter(|_| text.trim().get(..2).is_some_and(|p| p.eq_ignore_ascii_case("0x")));
    let (Family::Modbus, Some(Ok(hex))) = (protocol.family(), digits.map(|d| u32::from_str_radix(d, 16)))
    else {
        return String::new();
    };
    let n = address.index;
    let reference = if n < 9999 { format!("4{:04}", n + 1) } else { format!("4{:05}", n + 1) };
    format!(
        " ({text} is coil {n} in the Modicon area notation, not hex {hex}; holding register {n} is 4x{n} or \
         {reference})"
    )
}

/// An address in the protocol's notation (Modbus: the area notation).
pub fn format_address(protocol: Protocol, address: &Address) -> String {
    match protocol.family() {
        Family::Modbus => modbus::address::format(address),
        Family::Mc3e => mc3e::address::format_address(address),
        Family::Mewtocol => mewtocol::address::format(address),
        Family::Ppi => ppi::address::format(address),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target(protocol: Protocol, text: &str, format: Option<Format>) -> anyhow::Result<Target> {
        Target::new(protocol, text, format, Order::Abcd)
    }

    #[test]
    fn labels_name_the_first_word_of_each_item() {
        let vd = target(Protocol::Ppi, "VD4", None).unwrap();
        let items = vd.items(&[0x1234, 0x5678, 0, 7]).unwrap();
        let labels: Vec<_> = items.iter().map(|(a, s)| format!("{a} {}", s.text)).collect();
        assert_eq!(labels, ["VD4 305419896", "VD8 7"]);
        assert_eq!(vd.size(2).unwrap(), 4);
        let vw = target(Protocol::PpiTcp, "VW100", Some(Format::F32)).unwrap();
        let items = vw.items(&[0x4048, 0xF5C3, 0, 0]).unwrap();
        assert_eq!((items[0].0.as_str(), items[1].0.as_str()), ("VW100", "VW104"));
        let hr = target(Protocol::ModbusTcp, "40001", Some(Format::U32)).unwrap();
        assert_eq!(hr.items(&[0, 1, 0, 2]).unwrap()[1].0, "4x2");
        let dt = target(Protocol::Mewtocol, "DT100", Some(Format::I32)).unwrap();
        assert_eq!(dt.items(&[1, 0]).unwrap()[0].0, "DT100");
        let d = Target::new(Protocol::Mc3e, "D200", Some(Format::Ascii), Order::Cdab).unwrap();
        assert_eq!(
            d.items(&[0x4142, 0x4300]).unwrap(),
            [("D200".into(), Shown { text: "\"ABC\"".into(), json: "ABC".into() })]
        );
    }

    #[test]
    fn a_format_the_area_cannot_hold_is_refused_with_the_notation() {
        let err = target(Protocol::ModbusUdp, "0x10", Some(Format::F32)).unwrap_err().to_string();
        assert!(err.contains("coil 10 in the Modicon area notation, not hex 16;"), "{err}");
        assert!(err.contains("4x10 or 40011"), "{err}");
        let err = parse_bit("300", Protocol::ModbusTcp, "0x10").unwrap_err().to_string();
        assert!(err.contains("coil 10 in the Modicon"), "{err}");
        assert!(target(Protocol::Ppi, "VB0", Some(Format::F32)).is_err());
        assert!(target(Protocol::Ppi, "VD0", Some(Format::Ascii)).is_err());
        assert!(target(Protocol::Ppi, "Q0.1", None).unwrap().view.is_none());
        assert!(target(Protocol::ModbusTcp, "4x65535", Some(Format::U32)).unwrap().size(1).is_err());
        assert!(target(Protocol::ModbusTcp, "4x65534", Some(Format::U32)).unwrap().size(1).is_ok());
    }
}
