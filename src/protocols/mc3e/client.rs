//! The MC 3E/4E binary client: [`PlcMemory`] over a TCP or UDP [`Link`].
//!
//! Requests larger than one frame allows are split: 960 points per word-unit batch, 7168
//! per bit-unit batch. Word devices (D, W, R, ZR, SD, SW, TN, STN, CN) are read and written
//! in words only; bit devices (M, X, Y, B, L, SM, F, V, SB, timer/counter contacts and coils)
//! in bits, or in words of 16 points (bit 0 = the start device): `K4M100` through
//! [`PlcMemory`], or [`Mc3eClient::read_device_words`] on a bit device.
//!
//! With [`FrameKind::E4`] every request carries the next serial number (wrapping, starting
//! at 1) and only the reply echoing it is taken. The reads beyond the batch commands (type
//! name, random, blocks) are in [`super::client_reads`].

use std::time::Duration;

use async_trait::async_trait;
use tokio::sync::Mutex;

use super::address;
use super::device::{Device, MAX_DEVICE_NUMBER};
use super::frame::{self, FrameKind, MAX_BIT_POINTS, MAX_WORD_POINTS, Route};
use super::link::{Expect, Link, LinkConfig, TransportKind};
use super::request::{Command, Request};
use crate::protocols::transport::Backoff;
use crate::protocols::{Address, PlcError, PlcMemory, Protocol, Replies};

/// Everything configurable about one PLC connection.
#[derive(Clone, Debug)]
pub struct Mc3eConfig {
    /// Address, transport, timeout, retries and reconnect backoff.
    pub link: LinkConfig,
    /// Network, PC, module I/O and station numbers (default 00/FF/03FF/00).
    pub route: Route,
    /// CPU monitoring timer in units of 250 ms, sent in every request (0 = wait forever).
    /// Keep it below the timeout so the module gives up (and answers) before rackd does.
    pub monitor_timer: u16,
    /// 3E or 4E frames.
    pub frame: FrameKind,
}

impl Mc3eConfig {
    /// The protocol this configuration speaks.
    pub fn protocol(&self) -> Protocol {
        match (self.frame, self.link.transport) {
            (FrameKind::E3, TransportKind::Tcp) => Protocol::Mc3e,
            (FrameKind::E3, TransportKind::Udp) => Protocol::Mc3eUdp,
            (FrameKind::E4, TransportKind::Tcp) => Protocol::Mc4e,
            (FrameKind::E4, TransportKind::Udp) => Protocol::Mc4eUdp,
        }
    }

    /// Whether the replies name their request ([`Protocol::replies`]: 4E frames do).
    pub fn replies(&self) -> Replies {
        self.protocol().replies(&std::collections::BTreeSet::new())
    }

    /// Defaults for `HOST:PORT` over `transport`: route 00/FF/03FF/00, monitoring timer 4
    /// (1 s), timeout 1.5 s, 2 retries, reconnect backoff 100 ms doubling to 5 s, an
    /// ephemeral local UDP port, and no recorder.
    pub fn new(address: impl Into<String>, transport: TransportKind) -> Mc3eConfig {
        Mc3eConfig {
            link: LinkConfig {
                address: address.into(),
                transport,
                timeout: Duration::from_millis(1500),
                retries: 2,
                tuning: crate::protocols::transport::LinkTuning::default(),
                backoff: Backoff::default(),
                udp_local: None,
                capture: None,
            },
            route: Route::default(),
            monitor_timer: 4,
            frame: FrameKind::E3,
        }
    }
}

/// An MC 3E binary client for one PLC. Requests are sent one at a time.
pub struct Mc3eClient {
    route: Route,
    monitor_timer: u16,
    frame: FrameKind,
    serial: std::sync::atomic::AtomicU16,
    link: Mutex<Link>,
    health: std::sync::Arc<crate::protocols::transport::LinkHealth>,
}

impl Mc3eClient {
    /// A client for `config`; it connects on the first request.
    pub fn new(config: Mc3eConfig) -> Mc3eClient {
        let replies = config.replies();
        Self::with(&config, Link::new(config.link.clone(), replies))
    }

    /// A client over carriers the caller dials (the seeded wire simulation of the tests).
    pub fn over(
        config: Mc3eConfig,
        dial: std::sync::Arc<dyn crate::protocols::transport::Dial>,
    ) -> Mc3eClient {
        let link = Link::over(&config.link, config.replies(), dial);
        Self::with(&config, link)
    }

    fn with(config: &Mc3eConfig, link: Link) -> Mc3eClient {
        Mc3eClient {
            route: config.route,
            monitor_timer: config.monitor_timer,
            frame: config.frame,
            serial: std::sync::atomic::AtomicU16::new(0),
            health: link.health(),
            link: Mutex::new(link),
        }
    }

    /// Sends one command and returns the reply's data (end code 0), checked for length.
    pub(super) async fn send(&self, command: Command) -> Result<Vec<u8>, PlcError> {
        let mut link = self.link.lock().await;
        let serial = match self.frame {
            FrameKind::E3 => None,
            FrameKind::E4 => {
                let previous = self.serial.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                Some(previous.wrapping_add(1))
            }
        };
        let expect = Expect {
            serial,
            route: self.route,
            command: command.numbers(),
            data_len: command.reply_data_len(),
            write: command.is_write(),
        };
        let frame =
            Request { serial, route: self.route, monitor_timer: self.monitor_timer, command }.encode();
        link.exchange(&frame, &expect).await
    }

    /// Reads `count` words of `device` from `start`, split into batches of 960.
    pub async fn read_device_words(
        &self,
        device: Device,
        start: u32,
        count: usize,
    ) -> Result<Vec<u16>, PlcError> {
        check_range(device, start, count, if device.is_bit() { 16 } else { 1 })?;
        let mut words = Vec::with_capacity(count);
        for (offset, n) in batches(count, MAX_WORD_POINTS) {
            let start = start + offset * if device.is_bit() { 16 } else { 1 };
            let data = self.send(Command::ReadWords { device, start, count: n }).await?;
            words.extend(data.chunks_exact(2).map(|w| u16::from_le_bytes([w[0], w[1]])));
        }
        Ok(words)
    }

    /// Writes words of `device` from `start`, split into batches of 960.
    pub async fn write_device_words(
        &self,
        device: Device,
        start: u32,
        values: &[u16],
    ) -> Result<(), PlcError> {
        let unit: u32 = if device.is_bit() { 16 } else { 1 };
        check_range(device, start, values.len(), u64::from(unit))?;
        for (offset, n) in batches(values.len(), MAX_WORD_POINTS) {
            let chunk = values[offset as usize..offset as usize + usize::from(n)].to_vec();
            self.send(Command::WriteWords { device, start: start + offset * unit, values: chunk }).await?;
        }
        Ok(())
    }

    /// Reads `count` bits of a bit device from `start`, split into batches of 7168.
    pub async fn read_device_bits(
        &self,
        device: Device,
        start: u32,
        count: usize,
    ) -> Result<Vec<bool>, PlcError> {
        bit_device(device)?;
        check_range(device, start, count, 1)?;
        let mut bits = Vec::with_capacity(count);
        for (offset, n) in batches(count, MAX_BIT_POINTS) {
            let data = self.send(Command::ReadBits { device, start: start + offset, count: n }).await?;
            bits.extend(
                frame::unpack_bits(&data, usize::from(n))
                    .ok_or(PlcError::Malformed("bit data not 0 or 1"))?,
            );
        }
        Ok(bits)
    }

    /// Writes bits of a bit device from `start`, split into batches of 7168.
    pub async fn write_device_bits(
        &self,
        device: Device,
        start: u32,
        values: &[bool],
    ) -> Result<(), PlcError> {
        bit_device(device)?;
        check_range(device, start, values.len(), 1)?;
        for (offset, n) in batches(values.len(), MAX_BIT_POINTS) {
            let chunk = values[offset as usize..offset as usize + usize::from(n)].to_vec();
            self.send(Command::WriteBits { device, start: start + offset, values: chunk }).await?;
        }
        Ok(())
    }
}

/// `(offset, points)` of each batch of at most `max` points covering `count`.
fn batches(count: usize, max: u16) -> impl Iterator<Item = (u32, u16)> {
    (0..count).step_by(usize::from(max)).map(move |offset| {
        let n = (count - offset).min(usize::from(max));
        (offset as u32, n as u16)
    })
}

fn check_range(device: Device, start: u32, count: usize, unit: u64) -> Result<(), PlcError> {
    let last = u64::from(start) + (count as u64 * unit).saturating_sub(1);
    if last > u64::from(MAX_DEVICE_NUMBER) {
        return Err(PlcError::OutOfRange(match device.is_bit() {
            true => "device number past 0xFFFFFF (3-byte limit of 3E frames)",
            false => "device number past 16777215 (3-byte limit of 3E frames)",
        }));
    }
    Ok(())
}

fn bit_device(device: Device) -> Result<(), PlcError> {
    if device.is_bit() {
        Ok(())
    } else {
        Err(PlcError::OutOfRange(
            "word devices (D, W, R, ZR, SD, SW, TN, STN, CN) cannot be accessed in bit units",
        ))
    }
}

/// The device an address reads in words: a word device, or the bit device of a `K4` view.
pub(super) fn word_device(address: &Address) -> Result<Device, PlcError> {
    match address::word_view(&address.area) {
        Some(device) => Ok(device),
        None => Device::of_area(&address.area),
    }
}

/// The device an address reads in bits; a `K4` view is words only.
fn bit_address_device(address: &Address) -> Result<Device, PlcError> {
    if address::word_view(&address.area).is_some() {
        return Err(PlcError::OutOfRange("K4M100 names words of 16 bits; write M100 to read or write bits"));
    }
    Device::of_area(&address.area)
}

#[async_trait]
impl PlcMemory for Mc3eClient {
    fn parse_address(&self, text: &str) -> Result<Address, PlcError> {
        address::parse_address(text)
    }

    async fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        self.read_device_words(word_device(start)?, start.index, usize::from(count)).await
    }

    async fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        self.write_device_words(word_device(start)?, start.index, values).await
    }

    async fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        self.read_device_bits(bit_address_device(start)?, start.index, usize::from(count)).await
    }

    async fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        self.write_device_bits(bit_address_device(start)?, start.index, values).await
    }

    fn link_stats(&self) -> crate::protocols::transport::LinkStats {
        self.health.stats()
    }

    fn recorder(&self) -> Option<std::sync::Arc<crate::capture::Recorder>> {
        self.health.recorder().cloned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batches_split_at_the_limit() {
        assert_eq!(batches(2000, 960).collect::<Vec<_>>(), [(0, 960), (960, 960), (1920, 80)]);
        assert_eq!(batches(960, 960).collect::<Vec<_>>(), [(0, 960)]);
        assert_eq!(batches(0, 960).count(), 0);
    }

    #[test]
    fn range_checks() {
        assert!(check_range(Device::D, MAX_DEVICE_NUMBER, 1, 1).is_ok());
        assert!(check_range(Device::D, MAX_DEVICE_NUMBER, 2, 1).is_err());
        assert!(check_range(Device::M, MAX_DEVICE_NUMBER - 15, 1, 16).is_ok());
        assert!(check_range(Device::M, MAX_DEVICE_NUMBER - 14, 1, 16).is_err());
        assert!(bit_device(Device::D).is_err() && bit_device(Device::X).is_ok());
    }
}
