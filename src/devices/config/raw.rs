//! The flat form of a `[[devices]]` entry as the file writes it, and its conversion into
//! the typed [`DeviceConfig`]: defaults by kind and protocol filled in, keys of another
//! kind refused by name.

use std::collections::BTreeSet;
use std::time::Duration;

use serde::Deserialize;

use super::crane::{self, Ack, CraneConfig, Station};
use super::error::{DeviceConfigError, Problem};
use super::shelf::{ShelfConfig, default_shelf_quirks};
use super::tags::TagsConfig;
use super::{DeviceConfig, DeviceKind};
use crate::devices::tagdef::TagTable;
use crate::protocols::link::{DEFAULT_RETRIES, DEFAULT_TIMEOUT, LinkConfig};
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::LinkTuning;
use crate::protocols::{Protocol, Quirk};

/// Every key any kind has; unknown keys are refused here, keys of another kind in
/// [`TryFrom`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDevice {
    id: String,
    kind: DeviceKind,
    address: String,
    protocol: Option<Protocol>,
    unit: Option<u8>,
    serial: Option<String>,
    timeout_ms: Option<u64>,
    retries: Option<u32>,
    min_timeout_ms: Option<u64>,
    degraded_window: Option<u32>,
    degraded_above: Option<f64>,
    degraded_below: Option<f64>,
    quirks: Option<BTreeSet<Quirk>>,
    poll_ms: Option<u64>,
    offline_after: Option<u32>,
    aisles: Option<Vec<u16>>,
    // Shelf.
    dispatch_window: Option<u32>,
    slots: Option<u16>,
    base: Option<String>,
    stride: Option<u16>,
    clear_finished: Option<bool>,
    withdraw: Option<bool>,
    // Crane.
    wcs_base: Option<String>,
    crane_base: Option<String>,
    inbound_station: Option<Station>,
    outbound_station: Option<Station>,
    heartbeat_ms: Option<u64>,
    heartbeat_timeout_ms: Option<u64>,
    handshake_timeout_ms: Option<u64>,
    auto_cancel: Option<bool>,
    ack: Option<Ack>,
    // Tags.
    tags: Option<TagTable>,
}

impl RawDevice {
    /// The keys of other kinds that are set, with the kinds they belong to.
    fn foreign_keys(&self) -> Vec<(&'static str, &'static str)> {
        let shelf = [
            ("dispatch_window", self.dispatch_window.is_some()),
            ("slots", self.slots.is_some()),
            ("base", self.base.is_some()),
            ("stride", self.stride.is_some()),
            ("clear_finished", self.clear_finished.is_some()),
            ("withdraw", self.withdraw.is_some()),
        ];
        let crane = [
            ("wcs_base", self.wcs_base.is_some()),
            ("crane_base", self.crane_base.is_some()),
            ("inbound_station", self.inbound_station.is_some()),
            ("outbound_station", self.outbound_station.is_some()),
            ("heartbeat_ms", self.heartbeat_ms.is_some()),
            ("heartbeat_timeout_ms", self.heartbeat_timeout_ms.is_some()),
            ("handshake_timeout_ms", self.handshake_timeout_ms.is_some()),
            ("auto_cancel", self.auto_cancel.is_some()),
            ("ack", self.ack.is_some()),
        ];
        let mut set = Vec::new();
        let mut add = |keys: &[(&'static str, bool)], owners| {
            set.extend(keys.iter().filter(|(_, on)| *on).map(|&(key, _)| (key, owners)));
        };
        if self.kind != DeviceKind::Shelf {
            add(&shelf, "shelf");
        }
        if self.kind != DeviceKind::Crane {
            add(&crane, "crane");
        }
        if self.kind != DeviceKind::Tags {
            add(&[("tags", self.tags.is_some())], "tags");
        }
        if self.kind == DeviceKind::Tags {
            add(&[("aisles", self.aisles.is_some())], "shelf and crane");
        }
        set
    }

    /// The link section, with `protocol` and `timeout` defaulting as for `kind` and the
    /// rest as for the protocol.
    fn link(
        &self,
        protocol: Protocol,
        timeout: Duration,
        quirks: BTreeSet<Quirk>,
    ) -> Result<LinkConfig, Problem> {
        let serial = self.serial.as_deref().map(str::parse::<SerialSettings>).transpose()?;
        let d = LinkTuning::for_protocol(protocol);
        Ok(LinkConfig {
            protocol,
            address: self.address.clone(),
            unit: self.unit.unwrap_or(protocol.default_unit()),
            serial,
            timeout: self.timeout_ms.map_or(timeout, Duration::from_millis),
            retries: self.retries.unwrap_or(DEFAULT_RETRIES),
            quirks: self.quirks.clone().unwrap_or(quirks),
            tuning: LinkTuning {
                min_timeout: self.min_timeout_ms.map_or(d.min_timeout, Duration::from_millis),
                degraded_window: self.degraded_window.unwrap_or(d.degraded_window),
                degraded_above: self.degraded_above.unwrap_or(d.degraded_above),
                degraded_below: self.degraded_below.unwrap_or(d.degraded_below),
            },
        })
    }
}

impl TryFrom<RawDevice> for DeviceConfig {
    type Error = DeviceConfigError;

    fn try_from(raw: RawDevice) -> Result<Self, Self::Error> {
        let fail = |problem: Problem| DeviceConfigError::new(&raw.id, problem);
        if let Some(&(key, owners)) = raw.foreign_keys().first() {
            return Err(fail(Problem::ForeignKey { key, owners, kind: raw.kind }));
        }
        let poll_ms = raw.poll_ms.unwrap_or(super::defaults::POLL_MS);
        let offline_after = raw.offline_after.unwrap_or(super::defaults::OFFLINE_AFTER);
        Ok(match raw.kind {
            DeviceKind::Shelf => {
                let protocol = raw.protocol.unwrap_or(Protocol::ModbusUdp);
                let link =
                    raw.link(protocol, DEFAULT_TIMEOUT, default_shelf_quirks(protocol)).map_err(fail)?;
                let mut c = ShelfConfig::on(&raw.id, link, raw.aisles.unwrap_or_default());
                (c.poll_ms, c.offline_after) = (poll_ms, offline_after);
                c.dispatch_window = raw.dispatch_window.unwrap_or(c.dispatch_window);
                c.slots = raw.slots.unwrap_or(c.slots);
                c.base = raw.base.unwrap_or(c.base);
                c.stride = raw.stride.unwrap_or(c.stride);
                c.clear_finished = raw.clear_finished.unwrap_or(c.clear_finished);
                c.withdraw = raw.withdraw.unwrap_or(c.withdraw);
                DeviceConfig::Shelf(c)
            }
            DeviceKind::Crane => {
                let protocol = raw.protocol.unwrap_or(Protocol::Mc3e);
                let link = raw.link(protocol, crane::DEFAULT_TIMEOUT, BTreeSet::new()).map_err(fail)?;
                let mut c = CraneConfig::new(&raw.id, &raw.address, raw.aisles.unwrap_or_default());
                c.link = link;
                (c.poll_ms, c.offline_after) = (poll_ms, offline_after);
                c.wcs_base = raw.wcs_base.unwrap_or(c.wcs_base);
                c.crane_base = raw.crane_base.unwrap_or(c.crane_base);
                c.inbound_station = raw.inbound_station.unwrap_or(c.inbound_station);
                c.outbound_station = raw.outbound_station.unwrap_or(c.outbound_station);
                c.heartbeat_ms = raw.heartbeat_ms.unwrap_or(c.heartbeat_ms);
                c.heartbeat_timeout_ms = raw.heartbeat_timeout_ms.unwrap_or(c.heartbeat_timeout_ms);
                c.handshake_timeout_ms = raw.handshake_timeout_ms.unwrap_or(c.handshake_timeout_ms);
                c.auto_cancel = raw.auto_cancel.unwrap_or(c.auto_cancel);
                c.ack = raw.ack.unwrap_or(c.ack);
                DeviceConfig::Crane(c)
            }
            DeviceKind::Tags => {
                let protocol = raw.protocol.unwrap_or(Protocol::ModbusUdp);
                let link = raw.link(protocol, DEFAULT_TIMEOUT, BTreeSet::new()).map_err(fail)?;
                let mut c = TagsConfig::new(&raw.id, link, raw.tags.unwrap_or_default().0);
                (c.poll_ms, c.offline_after) = (poll_ms, offline_after);
                DeviceConfig::Tags(c)
            }
        })
    }
}
