//! The device memory a simulated PLC serves: word areas (D, W, R, ZR, SD, SW and the timer
//! and counter current values) and bit areas (M, X, Y, B, L, SM, F, V, SB and the timer and
//! counter contacts and coils), each with its own size. Timers and counters do not run: their
//! contacts, coils and current values are plain memory a simulator or a test sets.
//!
//! The server shares one bank as a [`SharedBank`] (`Arc<Mutex<Bank>>`): a simulator keeps a
//! clone, reads and changes registers between requests, and never holds the lock across an
//! `.await`. Errors are the end codes a PLC would answer.
//!
//! Read-only ranges ([`Bank::protect`]) refuse a master's writes ([`Bank::write_words`],
//! [`Bank::write_bits`], what the server calls) with end code C05B, "the target cannot read
//! or write the specified device" in the Q-series MC protocol manual's end code table: a
//! write-protected range is a device the target cannot write. The simulator's own writes
//! ([`Bank::set_words`], [`Bank::set_bits`], [`Bank::set_word`], [`Bank::set_bit`]) are the
//! field's and pass by them.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use super::device::Device;
use super::end_code;
use crate::protocols::read_only::{Overlap, ReadOnly};

/// A bank shared between the server and whoever simulates the machine.
pub type SharedBank = Arc<Mutex<Bank>>;

/// Device memory: words for word devices, bits for bit devices.
#[derive(Clone, Debug)]
pub struct Bank {
    words: BTreeMap<Device, Vec<u16>>,
    bits: BTreeMap<Device, Vec<bool>>,
    read_only: ReadOnly<Device>,
}

impl Default for Bank {
    /// Sizes of a Q-series CPU's default device assignment (X/Y/M/L/B 8192 points, D 12288,
    /// W 8192, SM/SD/F/V/SB/SW 2048, timers 2048, counters 1024), R one block of 32768, ZR
    /// 1,048,576 words, and 64 retentive timers (0 by default on a Q CPU; some, so that STN
    /// can be tried).
    fn default() -> Self {
        let sizes = [
            (Device::D, 12_288),
            (Device::W, 0x2000),
            (Device::R, 32_768),
            (Device::ZR, 1 << 20),
            (Device::M, 8_192),
            (Device::X, 0x2000),
            (Device::Y, 0x2000),
            (Device::B, 0x2000),
            (Device::L, 8_192),
            (Device::SM, 2_048),
            (Device::SD, 2_048),
            (Device::F, 2_048),
            (Device::V, 2_048),
            (Device::SB, 0x800),
            (Device::SW, 0x800),
            (Device::TS, 2_048),
            (Device::TC, 2_048),
            (Device::TN, 2_048),
            (Device::STS, 64),
            (Device::STC, 64),
            (Device::STN, 64),
            (Device::CS, 1_024),
            (Device::CC, 1_024),
            (Device::CN, 1_024),
        ];
        Bank::with_sizes(&sizes)
    }
}

impl Bank {
    /// A zeroed bank with the given number of points per device; devices not listed have
    /// none (every access to them is out of range).
    pub fn with_sizes(sizes: &[(Device, u32)]) -> Bank {
        let mut bank = Bank { words: BTreeMap::new(), bits: BTreeMap::new(), read_only: ReadOnly::default() };
        for &(device, size) in sizes {
            let size = size as usize;
            if device.is_bit() {
                bank.bits.insert(device, vec![false; size]);
            } else {
                bank.words.insert(device, vec![0; size]);
            }
        }
        bank
    }

    /// This bank wrapped for sharing with a server.
    pub fn shared(self) -> SharedBank {
        Arc::new(Mutex::new(self))
    }

    /// Number of points (words or bits) of a device.
    pub fn size(&self, device: Device) -> u32 {
        let len = if device.is_bit() {
            self.bits.get(&device).map(Vec::len)
        } else {
            self.words.get(&device).map(Vec::len)
        };
        len.unwrap_or(0) as u32
    }

    fn range(&self, device: Device, start: u32, points: usize) -> Result<std::ops::Range<usize>, u16> {
        let start = start as usize;
        let end = start.checked_add(points).ok_or(end_code::DEVICE_OUT_OF_RANGE)?;
        if points == 0 {
            return Err(end_code::POINTS_OUT_OF_RANGE);
        }
        if end > self.size(device) as usize {
            return Err(end_code::DEVICE_OUT_OF_RANGE);
        }
        Ok(start..end)
    }

    /// Reads `count` words; on a bit device each word packs 16 points, the first in bit 0.
    pub fn read_words(&self, device: Device, start: u32, count: u16) -> Result<Vec<u16>, u16> {
        if let Some(bits) = self.bits.get(&device) {
            let r = self.range(device, start, 16 * usize::from(count))?;
            return Ok(bits[r]
                .chunks(16)
                .map(|c| c.iter().rev().fold(0, |w, &b| (w << 1) | u16::from(b)))
                .collect());
        }
        let r = self.range(device, start, usize::from(count))?;
        Ok(self.words[&device][r].to_vec())
    }

    /// Makes `points` of `device` from `start` read-only to masters; refused if it
    /// overlaps an earlier read-only range of the device.
    pub fn protect(&mut self, device: Device, start: u32, points: u32) -> Result<(), Overlap> {
        self.read_only.add(device, u64::from(start)..u64::from(start) + u64::from(points))
    }

    /// The read-only ranges (device, points) and the master writes they refused so far.
    pub fn read_only(&self) -> &ReadOnly<Device> {
        &self.read_only
    }

    /// Refuses a master's write of `points` from `start` into a read-only range.
    fn guard(&mut self, device: Device, start: u32, points: usize) -> Result<(), u16> {
        let items = u64::from(start)..u64::from(start) + points as u64;
        if self.read_only.refuses(&device, items) { Err(end_code::DEVICE_NOT_ACCESSIBLE) } else { Ok(()) }
    }

    /// Writes words as a master does (read-only ranges refuse it); on a bit device each word
    /// sets 16 points, the first from bit 0.
    pub fn write_words(&mut self, device: Device, start: u32, values: &[u16]) -> Result<(), u16> {
        let unit = if device.is_bit() { 16 } else { 1 };
        self.range(device, start, unit * values.len())?;
        self.guard(device, start, unit * values.len())?;
        self.set_words(device, start, values)
    }

    /// Writes words as the field does, read-only ranges or not.
    pub fn set_words(&mut self, device: Device, start: u32, values: &[u16]) -> Result<(), u16> {
        if device.is_bit() {
            let r = self.range(device, start, 16 * values.len())?;
            let bits = self.bits.get_mut(&device).ok_or(end_code::DEVICE_OUT_OF_RANGE)?;
            for (i, slot) in bits[r].iter_mut().enumerate() {
                *slot = values[i / 16] & (1 << (i % 16)) != 0;
            }
            return Ok(());
        }
        let r = self.range(device, start, values.len())?;
        let words = self.words.get_mut(&device).ok_or(end_code::DEVICE_OUT_OF_RANGE)?;
        words[r].copy_from_slice(values);
        Ok(())
    }

    /// Reads `count` bits of a bit device (word devices: C05C, as in bit-unit requests).
    pub fn read_bits(&self, device: Device, start: u32, count: u16) -> Result<Vec<bool>, u16> {
        let bits = self.bits.get(&device).ok_or(Self::no_bits(device))?;
        let r = self.range(device, start, usize::from(count))?;
        Ok(bits[r].to_vec())
    }

    /// Writes bits of a bit device as a master does (read-only ranges refuse it).
    pub fn write_bits(&mut self, device: Device, start: u32, values: &[bool]) -> Result<(), u16> {
        if device.is_bit() {
            self.range(device, start, values.len())?;
            self.guard(device, start, values.len())?;
        }
        self.set_bits(device, start, values)
    }

    /// Writes bits of a bit device as the field does, read-only ranges or not.
    pub fn set_bits(&mut self, device: Device, start: u32, values: &[bool]) -> Result<(), u16> {
        let r = self.range(device, start, values.len())?;
        let bits = self.bits.get_mut(&device).ok_or(Self::no_bits(device))?;
        bits[r].copy_from_slice(values);
        Ok(())
    }

    fn no_bits(device: Device) -> u16 {
        if device.is_bit() { end_code::DEVICE_OUT_OF_RANGE } else { end_code::BAD_REQUEST_CONTENTS }
    }

    /// One word (0 when out of range): a convenience for simulators.
    pub fn word(&self, device: Device, number: u32) -> u16 {
        self.read_words(device, number, 1).map_or(0, |w| w[0])
    }

    /// Sets one word; false when out of range.
    pub fn set_word(&mut self, device: Device, number: u32, value: u16) -> bool {
        self.set_words(device, number, &[value]).is_ok()
    }

    /// One bit (false when out of range).
    pub fn bit(&self, device: Device, number: u32) -> bool {
        self.read_bits(device, number, 1).is_ok_and(|b| b[0])
    }

    /// Sets one bit; false when out of range.
    pub fn set_bit(&mut self, device: Device, number: u32, value: bool) -> bool {
        self.set_bits(device, number, &[value]).is_ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_and_ranges() {
        let mut bank = Bank::with_sizes(&[(Device::D, 10)]);
        assert!(bank.set_word(Device::D, 9, 7));
        assert_eq!(bank.read_words(Device::D, 8, 2), Ok(vec![0, 7]));
        assert_eq!(bank.read_words(Device::D, 9, 2), Err(0xC056));
        assert_eq!(bank.read_words(Device::D, 0, 0), Err(0xC051));
        assert_eq!(bank.read_words(Device::W, 0, 1), Err(0xC056));
        assert_eq!(bank.read_bits(Device::D, 0, 1), Err(0xC05C));
        assert_eq!(bank.read_words(Device::D, u32::MAX, 2), Err(0xC056));
    }

    #[test]
    fn bit_devices_in_word_units_pack_bit0_first() {
        let mut bank = Bank::with_sizes(&[(Device::M, 32)]);
        bank.set_bit(Device::M, 0, true);
        bank.set_bit(Device::M, 17, true);
        assert_eq!(bank.read_words(Device::M, 0, 2), Ok(vec![0x0001, 0x0002]));
        bank.write_words(Device::M, 16, &[0x8001]).unwrap();
        assert!(bank.bit(Device::M, 16) && bank.bit(Device::M, 31) && !bank.bit(Device::M, 17));
        assert_eq!(bank.write_words(Device::M, 17, &[1]), Err(0xC056));
    }

    #[test]
    fn read_only_ranges_refuse_masters_not_the_field() {
        let mut bank = Bank::with_sizes(&[(Device::D, 100), (Device::M, 64)]);
        bank.protect(Device::D, 10, 2).unwrap();
        bank.protect(Device::M, 20, 1).unwrap();
        assert!(bank.protect(Device::D, 11, 1).is_err(), "overlap");
        assert_eq!(bank.write_words(Device::D, 8, &[1, 2, 3]), Err(0xC05B));
        assert_eq!(bank.word(Device::D, 8), 0, "nothing written");
        assert_eq!(bank.write_words(Device::D, 12, &[5]), Ok(()));
        assert_eq!(bank.write_words(Device::M, 16, &[0xFFFF]), Err(0xC05B), "16 points cover M20");
        assert_eq!(bank.write_bits(Device::M, 20, &[true]), Err(0xC05B));
        assert_eq!(bank.write_words(Device::D, 99, &[1, 2]), Err(0xC056), "range first");
        assert_eq!(bank.read_only().refused(), 3);
        bank.set_words(Device::D, 10, &[7, 8]).unwrap();
        assert!(bank.set_bit(Device::M, 20, true));
        assert_eq!(bank.read_words(Device::D, 10, 2), Ok(vec![7, 8]));
    }
}
