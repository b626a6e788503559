//! Reads of scattered devices: random read in word units (0403) and multiple-block batch
//! read (0406), their bytes and the manual's limits.
//!
//! Limits (MELSEC-Q/L MC protocol reference manual, SH-080008, 3E frame to a QCPU/LCPU):
//! - random read: 1 to 192 access points, counting one per word and one per double word;
//! - multiple blocks: 1 to 120 blocks (word and bit blocks together), and at most 960 points
//!   in all, a bit block's points counting in words of 16 bits.
//!
//! The client checks them before sending ([`check_random`], [`check_blocks`]: a typed
//! [`PlcError::OutOfRange`] saying what to change); the server answers C051 to a request past
//! them, as it does to an over-long batch read.

use super::device::Device;
use super::end_code;
use super::frame::MAX_WORD_POINTS;
use crate::protocols::PlcError;

/// Most access points (words plus double words) of one random read.
pub const MAX_RANDOM_POINTS: usize = 192;
/// Most blocks (word plus bit blocks) of one multiple-block read.
pub const MAX_BLOCKS: usize = 120;

/// A run of consecutive devices: `points` words (a bit device: words of 16 bits).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Block {
    /// The device.
    pub device: Device,
    /// The first device number.
    pub start: u32,
    /// Number of points (words).
    pub points: u16,
}

impl Block {
    /// A block of `points` (saturating at 65535: callers keep to the limits).
    pub fn new(device: Device, start: u32, points: usize) -> Block {
        Block { device, start, points: u16::try_from(points).unwrap_or(u16::MAX) }
    }
}

fn put_device(out: &mut Vec<u8>, device: Device, number: u32) {
    out.extend_from_slice(&number.to_le_bytes()[..3]);
    out.push(device.code());
}

/// Appends device number (3), device code (1) and points (2).
pub(crate) fn put_block(out: &mut Vec<u8>, block: &Block) {
    put_device(out, block.device, block.start);
    out.extend_from_slice(&block.points.to_le_bytes());
}

fn count_byte(n: usize) -> u8 {
    u8::try_from(n).unwrap_or(u8::MAX)
}

pub(crate) fn encode_random(words: &[(Device, u32)], dwords: &[(Device, u32)], out: &mut Vec<u8>) {
    out.push(count_byte(words.len()));
    out.push(count_byte(dwords.len()));
    for &(device, number) in words.iter().chain(dwords) {
        put_device(out, device, number);
    }
}

pub(crate) fn encode_blocks(words: &[Block], bits: &[Block], out: &mut Vec<u8>) {
    out.push(count_byte(words.len()));
    out.push(count_byte(bits.len()));
    words.iter().chain(bits).for_each(|b| put_block(out, b));
}

fn device_at(bytes: &[u8]) -> Result<(Device, u32), u16> {
    let device = Device::from_code(bytes[3]).ok_or(end_code::DEVICE_NOT_ACCESSIBLE)?;
    Ok((device, u32::from_le_bytes([bytes[0], bytes[1], bytes[2], 0])))
}

/// Devices by number, one point each.
type Points = Vec<(Device, u32)>;

/// The devices of a random read (0403) after the subcommand: words, then double words.
pub(crate) fn decode_random(data: &[u8]) -> Result<(Points, Points), u16> {
    let [w, d, specs @ ..] = data else { return Err(end_code::LENGTH_MISMATCH) };
    let (w, d) = (usize::from(*w), usize::from(*d));
    if specs.len() != 4 * (w + d) {
        return Err(end_code::LENGTH_MISMATCH);
    }
    let devices = specs.chunks_exact(4).map(device_at).collect::<Result<Vec<_>, u16>>()?;
    let (words, dwords) = devices.split_at(w);
    Ok((words.to_vec(), dwords.to_vec()))
}

/// The blocks of a multiple-block read (0406) after the subcommand: word blocks, then bit
/// blocks.
pub(crate) fn decode_blocks(data: &[u8]) -> Result<(Vec<Block>, Vec<Block>), u16> {
    let [w, b, specs @ ..] = data else { return Err(end_code::LENGTH_MISMATCH) };
    let (w, b) = (usize::from(*w), usize::from(*b));
    if specs.len() != 6 * (w + b) {
        return Err(end_code::LENGTH_MISMATCH);
    }
    let mut blocks = Vec::with_capacity(w + b);
    for spec in specs.chunks_exact(6) {
        let (device, start) = device_at(spec)?;
        blocks.push(Block { device, start, points: u16::from_le_bytes([spec[4], spec[5]]) });
    }
    let bits = blocks.split_off(w);
    if blocks.iter().any(|b| b.device.is_bit()) || bits.iter().any(|b| !b.device.is_bit()) {
        return Err(end_code::BAD_REQUEST_CONTENTS);
    }
    Ok((blocks, bits))
}

/// Why a random read cannot be sent as one request, if it cannot.
pub fn check_random(words: usize, dwords: usize) -> Result<(), PlcError> {
    match words + dwords {
        0 => Err(PlcError::OutOfRange("a random read needs at least one device")),
        n if n > MAX_RANDOM_POINTS => Err(PlcError::OutOfRange(
            "a random read takes at most 192 devices (words plus double words): split it",
        )),
        _ => Ok(()),
    }
}

/// Why a multiple-block read cannot be sent as one request, if it cannot.
pub fn check_blocks(blocks: &[Block]) -> Result<(), PlcError> {
    let points: usize = blocks.iter().map(|b| usize::from(b.points)).sum();
    if blocks.is_empty() || blocks.iter().any(|b| b.points == 0) {
        return Err(PlcError::OutOfRange("a block read needs at least one block of at least one word"));
    }
    if blocks.len() > MAX_BLOCKS {
        return Err(PlcError::OutOfRange("a block read takes at most 120 blocks: split it"));
    }
    if points > usize::from(MAX_WORD_POINTS) {
        return Err(PlcError::OutOfRange(
            "a block read takes at most 960 words in all (a bit block counts 16 bits a word): split it",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::command::Command;
    use super::*;

    #[test]
    fn random_read_manual_example() {
        // The random read (0403) example of the MC protocol reference manual (iQ-R SH-081338
        // 8.3 with the Q/L subcommand; the same in SH-080008): words D0, T0 (current value),
        // M100, X20; double words D1500, Y160, M1111. The manual prints it in ASCII; these are
        // its binary bytes (counts, then device number LE and code per device).
        let words = vec![(Device::D, 0), (Device::TN, 0), (Device::M, 100), (Device::X, 0x20)];
        let dwords = vec![(Device::D, 1500), (Device::Y, 0x160), (Device::M, 1111)];
        let command = Command::RandomRead { words, dwords };
        let mut out = Vec::new();
        command.encode(&mut out);
        let manual = [
            0x04, 0x03, 0x00, 0x00, 0x00, 0xA8, 0x00, 0x00, 0x00, 0xC2, 0x64, 0x00, 0x00, 0x90, 0x20, 0x00,
            0x00, 0x9C, 0xDC, 0x05, 0x00, 0xA8, 0x60, 0x01, 0x00, 0x9D, 0x57, 0x04, 0x00, 0x90,
        ];
        assert_eq!(out, manual);
        assert_eq!(Command::decode(0x0403, 0, &manual), Ok(command.clone()));
        assert_eq!(command.reply_data_len(), 4 * 2 + 3 * 4);
        assert_eq!(Command::decode(0x0403, 0, &manual[..29]), Err(0xC061));
        let mut unknown = manual;
        unknown[5] = 0x01;
        assert_eq!(Command::decode(0x0403, 0, &unknown), Err(0xC05B));
    }

    #[test]
    fn block_read_manual_example() {
        // Multiple-block batch read (0406), message format of the same manual (8.4): block
        // counts, word blocks, then bit blocks (points in words). Blocks: D0..D3, W100..W107;
        // M0..M31, M128..M159, B100..B12F.
        let words = vec![Block::new(Device::D, 0, 4), Block::new(Device::W, 0x100, 8)];
        let bits =
            vec![Block::new(Device::M, 0, 2), Block::new(Device::M, 128, 2), Block::new(Device::B, 0x100, 3)];
        let command = Command::ReadBlocks { words, bits };
        let mut out = Vec::new();
        command.encode(&mut out);
        let manual = [
            0x02, 0x03, 0x00, 0x00, 0x00, 0xA8, 0x04, 0x00, 0x00, 0x01, 0x00, 0xB4, 0x08, 0x00, 0x00, 0x00,
            0x00, 0x90, 0x02, 0x00, 0x80, 0x00, 0x00, 0x90, 0x02, 0x00, 0x00, 0x01, 0x00, 0xA0, 0x03, 0x00,
        ];
        assert_eq!(out, manual);
        assert_eq!(Command::decode(0x0406, 0, &manual), Ok(command.clone()));
        assert_eq!(command.reply_data_len(), 2 * (4 + 8 + 2 + 2 + 3));
        let mut swapped = manual;
        swapped[5] = 0x90; // a bit device among the word blocks
        assert_eq!(Command::decode(0x0406, 0, &swapped), Err(0xC05C));
        assert_eq!(Command::decode(0x0406, 0, &manual[..31]), Err(0xC061));
    }

    #[test]
    fn limits() {
        assert!(check_random(96, 96).is_ok());
        assert!(check_random(192, 1).is_err() && check_random(0, 0).is_err());
        let one = Block::new(Device::D, 0, 8);
        assert!(check_blocks(&vec![one; 120]).is_ok());
        assert!(check_blocks(&vec![one; 121]).is_err());
        assert!(check_blocks(&[Block::new(Device::D, 0, 960)]).is_ok());
        assert!(check_blocks(&[Block::new(Device::D, 0, 900), Block::new(Device::M, 0, 61)]).is_err());
        assert!(check_blocks(&[]).is_err() && check_blocks(&[Block::new(Device::D, 0, 0)]).is_err());
        let too_many = Command::RandomRead { words: vec![(Device::D, 0); 193], dwords: vec![] };
        assert_eq!(too_many.refusal(), Some(0xC051));
        assert_eq!(Command::ReadTypeName.refusal(), None);
    }
}
