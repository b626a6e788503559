//! What a request asks for: the [`Command`] enum, its numbers, its bytes after the
//! subcommand, and the size of a normal reply.
//!
//! ```text
//! batch  (0401, 1401): device no(3) code(1) points(2) [data]
//! type name    (0101): nothing
//! random read  (0403): words(1) dwords(1) | device no(3) code(1) per word, then per dword
//! blocks       (0406): word blocks(1) bit blocks(1) | device no(3) code(1) points(2) per block
//! ```
//! Random and block reads are in [`super::scattered`].

use super::device::Device;
use super::end_code;
use super::frame;
use super::scattered::{self, Block};

/// Batch read command.
pub const CMD_BATCH_READ: u16 = 0x0401;
/// Batch write command.
pub const CMD_BATCH_WRITE: u16 = 0x1401;
/// Read CPU model name (type name) command.
pub const CMD_READ_TYPE_NAME: u16 = 0x0101;
/// Random read in word units command.
pub const CMD_RANDOM_READ: u16 = 0x0403;
/// Multiple-block batch read command.
pub const CMD_READ_BLOCKS: u16 = 0x0406;
/// Subcommand: word units (Q/L device specification).
pub const SUB_WORDS: u16 = 0x0000;
/// Subcommand: bit units (Q/L device specification).
pub const SUB_BITS: u16 = 0x0001;

/// What a request asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Command {
    /// Batch read in word units (0401/0000); on a bit device each word is 16 points.
    ReadWords {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// Number of words.
        count: u16,
    },
    /// Batch write in word units (1401/0000).
    WriteWords {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// The words.
        values: Vec<u16>,
    },
    /// Batch read in bit units (0401/0001).
    ReadBits {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// Number of bits.
        count: u16,
    },
    /// Batch write in bit units (1401/0001).
    WriteBits {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// The bits.
        values: Vec<bool>,
    },
    /// Read the CPU's model name and model code (0101/0000).
    ReadTypeName,
    /// Random read in word units (0403/0000): words, then double words (low word first), at
    /// scattered devices; a bit device counts 16 (or 32) points from the number given.
    RandomRead {
        /// Devices read as one word each.
        words: Vec<(Device, u32)>,
        /// Devices read as one double word each.
        dwords: Vec<(Device, u32)>,
    },
    /// Multiple-block batch read (0406/0000): word-device blocks, then bit-device blocks whose
    /// points are words of 16 bits.
    ReadBlocks {
        /// Blocks of word devices.
        words: Vec<Block>,
        /// Blocks of bit devices, in words.
        bits: Vec<Block>,
    },
}

impl Command {
    /// Whether the command changes the PLC's memory (a write), rather than reads it.
    pub fn is_write(&self) -> bool {
        matches!(self, Command::WriteWords { .. } | Command::WriteBits { .. })
    }

    /// The command and subcommand numbers.
    pub fn numbers(&self) -> (u16, u16) {
        match self {
            Command::ReadWords { .. } => (CMD_BATCH_READ, SUB_WORDS),
            Command::WriteWords { .. } => (CMD_BATCH_WRITE, SUB_WORDS),
            Command::ReadBits { .. } => (CMD_BATCH_READ, SUB_BITS),
            Command::WriteBits { .. } => (CMD_BATCH_WRITE, SUB_BITS),
            Command::ReadTypeName => (CMD_READ_TYPE_NAME, SUB_WORDS),
            Command::RandomRead { .. } => (CMD_RANDOM_READ, SUB_WORDS),
            Command::ReadBlocks { .. } => (CMD_READ_BLOCKS, SUB_WORDS),
        }
    }

    /// Bytes of data a normal response to this command carries after the end code.
    pub fn reply_data_len(&self) -> usize {
        match self {
            Command::ReadWords { count, .. } => 2 * usize::from(*count),
            Command::ReadBits { count, .. } => frame::bit_bytes(usize::from(*count)),
            Command::WriteWords { .. } | Command::WriteBits { .. } => 0,
            Command::ReadTypeName => super::type_name::TypeName::LEN,
            Command::RandomRead { words, dwords } => 2 * words.len() + 4 * dwords.len(),
            Command::ReadBlocks { words, bits } => {
                words.iter().chain(bits).map(|b| 2 * usize::from(b.points)).sum()
            }
        }
    }

    /// The lowest device number the command names (0 when it names none).
    pub fn first_device_number(&self) -> u32 {
        match self {
            Command::ReadWords { start, .. }
            | Command::WriteWords { start, .. }
            | Command::ReadBits { start, .. }
            | Command::WriteBits { start, .. } => *start,
            _ => 0,
        }
    }

    /// Appends the bytes after the subcommand.
    pub(crate) fn encode(&self, out: &mut Vec<u8>) {
        match self {
            Command::ReadWords { device, start, count } | Command::ReadBits { device, start, count } => {
                scattered::put_block(out, &Block { device: *device, start: *start, points: *count })
            }
            Command::WriteWords { device, start, values } => {
                scattered::put_block(out, &Block::new(*device, *start, values.len()));
                values.iter().for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
            }
            Command::WriteBits { device, start, values } => {
                scattered::put_block(out, &Block::new(*device, *start, values.len()));
                frame::pack_bits(values, out);
            }
            Command::ReadTypeName => {}
            Command::RandomRead { words, dwords } => scattered::encode_random(words, dwords, out),
            Command::ReadBlocks { words, bits } => scattered::encode_blocks(words, bits, out),
        }
    }

    /// Decodes a command from its numbers and the bytes after the subcommand, or returns the
    /// end code a PLC would answer. Point-count limits are not checked here (the server
    /// does, so the codec can carry any count).
    pub fn decode(command: u16, subcommand: u16, data: &[u8]) -> Result<Command, u16> {
        match (command, subcommand) {
            (CMD_READ_TYPE_NAME, SUB_WORDS) if data.is_empty() => Ok(Command::ReadTypeName),
            (CMD_READ_TYPE_NAME, SUB_WORDS) => Err(end_code::LENGTH_MISMATCH),
            (CMD_RANDOM_READ, SUB_WORDS) => {
                scattered::decode_random(data).map(|(words, dwords)| Command::RandomRead { words, dwords })
            }
            (CMD_READ_BLOCKS, SUB_WORDS) => {
                scattered::decode_blocks(data).map(|(words, bits)| Command::ReadBlocks { words, bits })
            }
            (CMD_BATCH_READ | CMD_BATCH_WRITE, SUB_WORDS) => decode_batch(command, false, data),
            (CMD_BATCH_READ | CMD_BATCH_WRITE, SUB_BITS) => decode_batch(command, true, data),
            _ => Err(end_code::UNKNOWN_COMMAND),
        }
    }

    /// The end code a server answers to a random read or block read past the manual's
    /// limits ([`scattered::check_random`], [`scattered::check_blocks`]), if any.
    pub fn refusal(&self) -> Option<u16> {
        let ok = match self {
            Command::RandomRead { words, dwords } => scattered::check_random(words.len(), dwords.len()),
            Command::ReadBlocks { words, bits } => {
                scattered::check_blocks(&words.iter().chain(bits).copied().collect::<Vec<_>>())
            }
            _ => Ok(()),
        };
        ok.err().map(|_| end_code::POINTS_OUT_OF_RANGE)
    }
}

fn decode_batch(command: u16, bits: bool, data: &[u8]) -> Result<Command, u16> {
    let [n0, n1, n2, code, c0, c1, rest @ ..] = data else { return Err(end_code::LENGTH_MISMATCH) };
    let start = u32::from_le_bytes([*n0, *n1, *n2, 0]);
    let count = u16::from_le_bytes([*c0, *c1]);
    let device = Device::from_code(*code).ok_or(end_code::DEVICE_NOT_ACCESSIBLE)?;
    if bits && !device.is_bit() {
        return Err(end_code::BAD_REQUEST_CONTENTS);
    }
    let expect_rest = match (command, bits) {
        (CMD_BATCH_READ, _) => 0,
        (_, false) => 2 * usize::from(count),
        (_, true) => frame::bit_bytes(usize::from(count)),
    };
    if rest.len() != expect_rest {
        return Err(end_code::LENGTH_MISMATCH);
    }
    Ok(match (command, bits) {
        (CMD_BATCH_READ, false) => Command::ReadWords { device, start, count },
        (CMD_BATCH_READ, true) => Command::ReadBits { device, start, count },
        (_, false) => Command::WriteWords {
            device,
            start,
            values: rest.chunks_exact(2).map(|w| u16::from_le_bytes([w[0], w[1]])).collect(),
        },
        (_, true) => Command::WriteBits {
            device,
            start,
            values: frame::unpack_bits(rest, usize::from(count)).ok_or(end_code::BAD_REQUEST_DATA)?,
        },
    })
}
