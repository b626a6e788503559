//! The client's reads beyond the batch commands: the CPU's model name (0101), random read
//! (0403) and multiple-block batch read (0406).
//!
//! Addresses are taken in rackd's notation: a word device (`D100`, `TN5`) or a bit device in
//! words (`K4M100`, 16 points per word). A plain bit device (`M100`) is refused with a hint
//! to write `K4M100`, so a reader never wonders whether a word or a bit came back. Limits
//! (192 random points; 120 blocks, 960 words) are checked before anything is sent.

use super::client::{Mc3eClient, word_device};
use super::command::Command;
use super::device::{Device, MAX_DEVICE_NUMBER};
use super::scattered::{self, Block};
use super::type_name::TypeName;
use crate::protocols::{Address, PlcError};

/// Blocks with their place in the caller's list.
type Numbered = Vec<(usize, Block)>;

fn device_of(address: &Address) -> Result<Device, PlcError> {
    let device = word_device(address)?;
    if device.is_bit() && super::address::word_view(&address.area).is_none() {
        return Err(PlcError::OutOfRange("a bit device is read here in words: write K4M100, not M100"));
    }
    Ok(device)
}

fn spec(address: &Address, points: u32) -> Result<(Device, u32), PlcError> {
    let device = device_of(address)?;
    let unit = if device.is_bit() { 16 } else { 1 };
    if u64::from(address.index) + u64::from(points * unit) - 1 > u64::from(MAX_DEVICE_NUMBER) {
        return Err(PlcError::OutOfRange("device number past 0xFFFFFF (3-byte limit of 3E/4E frames)"));
    }
    Ok((device, address.index))
}

impl Mc3eClient {
    /// Reads the CPU's model name and model code (command 0101).
    pub async fn read_type_name(&self) -> Result<TypeName, PlcError> {
        TypeName::decode(&self.send(Command::ReadTypeName).await?)
    }

    /// Reads one word at each of `words` and one double word (low word first, as the PLC
    /// stores 32-bit values) at each of `dwords`, in one random read (command 0403).
    pub async fn read_random(
        &self,
        words: &[Address],
        dwords: &[Address],
    ) -> Result<(Vec<u16>, Vec<u32>), PlcError> {
        scattered::check_random(words.len(), dwords.len())?;
        let words = words.iter().map(|a| spec(a, 1)).collect::<Result<Vec<_>, _>>()?;
        let dwords = dwords.iter().map(|a| spec(a, 2)).collect::<Result<Vec<_>, _>>()?;
        let split = words.len();
        let data = self.send(Command::RandomRead { words, dwords }).await?;
        let (w, d) = data.split_at(2 * split);
        Ok((
            w.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect(),
            d.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
        ))
    }

    /// Reads `count` words from each start address in one multiple-block read (command
    /// 0406); the blocks come back in the order given. Word devices make word blocks, `K4`
    /// bit devices bit blocks (the protocol sends word blocks first; rackd restores the order).
    pub async fn read_blocks(&self, blocks: &[(Address, u16)]) -> Result<Vec<Vec<u16>>, PlcError> {
        let mut specs = Vec::with_capacity(blocks.len());
        for (address, count) in blocks {
            let (device, start) = spec(address, u32::from(*count).max(1))?;
            specs.push(Block { device, start, points: *count });
        }
        scattered::check_blocks(&specs)?;
        let (bits, words): (Numbered, Numbered) =
            specs.into_iter().enumerate().partition(|(_, b)| b.device.is_bit());
        let order: Vec<(usize, Block)> = words.iter().chain(&bits).copied().collect();
        let command = Command::ReadBlocks {
            words: words.into_iter().map(|(_, b)| b).collect(),
            bits: bits.into_iter().map(|(_, b)| b).collect(),
        };
        let data = self.send(command).await?;
        let mut out = vec![Vec::new(); order.len()];
        let mut at = 0;
        for (index, block) in order {
            let n = 2 * usize::from(block.points);
            out[index] = data[at..at + n].chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
            at += n;
        }
        Ok(out)
    }
}
