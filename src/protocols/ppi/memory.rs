//! [`PlcMemory`] for the PPI client (see [`super::address`] for the notation and how
//! `Address.index` maps to byte offsets). Requests are split at 200 data bytes.
//!
//! - Words (`VW`, `AIW`, ...): big-endian, `read_words(VW100, n)` covers bytes 100..100+2n.
//! - Bytes (`VB`, ...): one byte per word value; writing a value above 255 is refused.
//! - Double words (`VD`, ...): an even number of words, high word first.
//! - Timers and counters (`T`, `C`): the current value, one word each.
//! - Bits: one with bit access; more are read as the bytes that hold them (bit 0 is the
//!   lowest). Bit writes go one bit per request (bit access), never read-modify-write, so
//!   the PLC's own changes to neighbouring bits are not overwritten.

use async_trait::async_trait;

use super::address::{self, Target};
use super::client::PpiClient;
use super::pdu::{Item, MAX_DATA, Size};
use crate::protocols::{Address, PlcError, PlcMemory};

fn words_target(start: &Address) -> Result<Target, PlcError> {
    let target = address::resolve(start)?;
    if target.size == Size::Bit {
        return Err(PlcError::OutOfRange("bits are read and written with read_bits / write_bits"));
    }
    Ok(target)
}

/// Elements of `size` per request, and the index step per element.
fn per_request(size: Size) -> (usize, u32) {
    match size {
        Size::Timer | Size::Counter => (MAX_DATA / 2, 1),
        other => (MAX_DATA / other.bytes(), other.bytes() as u32),
    }
}

fn offset(target: &Target, first: u32) -> u32 {
    match target.size {
        Size::Timer | Size::Counter => first,
        _ => first * 8,
    }
}

fn to_words(size: Size, bytes: &[u8]) -> Vec<u16> {
    match size {
        Size::Byte => bytes.iter().map(|&b| b.into()).collect(),
        _ => bytes.chunks(2).map(|c| u16::from_be_bytes([c[0], *c.get(1).unwrap_or(&0)])).collect(),
    }
}

#[async_trait]
impl PlcMemory for PpiClient {
    fn link_stats(&self) -> crate::protocols::transport::LinkStats {
        self.link_stats()
    }

    fn recorder(&self) -> Option<std::sync::Arc<crate::capture::Recorder>> {
        self.recorder()
    }

    fn parse_address(&self, text: &str) -> Result<Address, PlcError> {
        address::parse(text)
    }

    fn word_address(&self, start: &Address, words: u32) -> Address {
        start.offset(address::step(start) * words)
    }

    async fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let target = words_target(start)?;
        let elements = match target.size {
            Size::DWord if !count.is_multiple_of(2) => {
                return Err(PlcError::OutOfRange("double words are read as an even number of words"));
            }
            Size::DWord => count as usize / 2,
            _ => count as usize,
        };
        let (max, step) = per_request(target.size);
        let mut out = Vec::with_capacity(count as usize);
        let mut done = 0;
        while done < elements {
            let n = (elements - done).min(max);
            let first = target.index + done as u32 * step;
            let item = Item {
                size: target.size,
                count: n as u16,
                area: target.area,
                offset: offset(&target, first),
            };
            out.extend(to_words(target.size, &self.read(item).await?));
            done += n;
        }
        Ok(out)
    }

    async fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        let target = words_target(start)?;
        let bytes: Vec<u8> = match target.size {
            Size::Byte => values
                .iter()
                .map(|&v| u8::try_from(v).map_err(|_| PlcError::OutOfRange("byte values are 0..=255")))
                .collect::<Result<_, _>>()?,
            Size::DWord if !values.len().is_multiple_of(2) => {
                return Err(PlcError::OutOfRange("double words are written as an even number of words"));
            }
            _ => values.iter().flat_map(|v| v.to_be_bytes()).collect(),
        };
        let (max, step) = per_request(target.size);
        let per = target.size.bytes();
        for (i, chunk) in bytes.chunks(max * per).enumerate() {
            let first = target.index + (i * max) as u32 * step;
            let n = (chunk.len() / per) as u16;
            let item =
                Item { size: target.size, count: n, area: target.area, offset: offset(&target, first) };
            self.write(item, chunk).await?;
        }
        Ok(())
    }

    async fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        let target = address::resolve(start)?;
        if target.size != Size::Bit {
            return Err(PlcError::OutOfRange("words are read with read_words"));
        }
        let first = target.index;
        if count == 1 {
            let item = Item { size: Size::Bit, count: 1, area: target.area, offset: first };
            return Ok(vec![self.read(item).await?.first().is_some_and(|b| b & 1 != 0)]);
        }
        if count == 0 {
            return Ok(Vec::new());
        }
        let (b0, b1) = (first / 8, (first + count as u32 - 1) / 8);
        let mut bytes = Vec::new();
        let mut b = b0;
        while b <= b1 {
            let n = (b1 - b + 1).min(MAX_DATA as u32);
            let item = Item { size: Size::Byte, count: n as u16, area: target.area, offset: b * 8 };
            bytes.extend(self.read(item).await?);
            b += n;
        }
        Ok((first..first + count as u32)
            .map(|i| bytes[(i / 8 - b0) as usize] & (1 << (i % 8)) != 0)
            .collect())
    }

    async fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        let target = address::resolve(start)?;
        if target.size != Size::Bit {
            return Err(PlcError::OutOfRange("words are written with write_words"));
        }
        for (i, &v) in values.iter().enumerate() {
            let item = Item { size: Size::Bit, count: 1, area: target.area, offset: target.index + i as u32 };
            self.write(item, &[u8::from(v)]).await?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocols::ppi::{PpiConfig, PpiTransport};

    #[test]
    fn word_addresses_step_by_the_bytes_a_word_takes() {
        let plc = PpiClient::new(PpiConfig::new(PpiTransport::Tcp, "127.0.0.1:9")).unwrap();
        let at = |t: &str| plc.parse_address(t).unwrap();
        assert_eq!(plc.word_address(&at("VW1000"), 50), at("VW1100"), "a slot of 50 words");
        assert_eq!(plc.word_address(&at("VD4"), 2), at("VD8"), "two words, one double word");
        assert_eq!(plc.word_address(&at("VB10"), 3), at("VB13"), "one byte per word value");
        assert_eq!(plc.word_address(&at("T37"), 1), at("T38"));
    }
}
