//! The flat form of a `[[devices]]` entry as the file writes it, and its conversion into
//! the typed [`DeviceConfig`]: defaults by kind and protocol filled in, keys of another
//! kind refused by name.

use std::collections::BTreeSet;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::address::{AddressError, check_unit};
use super::crane::{self, Ack, CraneConfig, Planner, Station};
use super::error::{DeviceConfigError, Problem};
use super::shelf::{ShelfConfig, default_shelf_quirks};
use super::tags::TagsConfig;
use super::unit::Unit;
use super::{DeviceConfig, DeviceKind};
use crate::capture::Limits;
use crate::protocols::link::{DEFAULT_RETRIES, DEFAULT_TIMEOUT, LinkConfig};
use crate::protocols::mewtocol::frame::GLOBAL_STATION;
use crate::protocols::protocol::Family;
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::LinkTuning;
use crate::protocols::{Protocol, Quirk};
use crate::wire::motion::Motion;
use crate::wire::tags::TagTable;

/// Every key any kind has; unknown keys are refused here, keys of another kind in
/// [`TryFrom`]. Written back ([`From<&DeviceConfig>`]) with every key of the entry's kind
/// filled in, it is what `rackd check-config --explain` prints.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RawDevice {
    id: String,
    kind: DeviceKind,
    address: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    protocol: Option<Protocol>,
    /// Wider than any protocol's unit, so that `unit = 300` is refused with the protocol's
    /// range rather than serde's "expected u8"; or `"EE"`, MEWTOCOL's global station.
    #[serde(skip_serializing_if = "Option::is_none")]
    unit: Option<Unit>,
    #[serde(skip_serializing_if = "Option::is_none")]
    serial: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    timeout_ms: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    retries: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    min_timeout_ms: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    degraded_window: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    degraded_above: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    degraded_below: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    quirks: Option<BTreeSet<Quirk>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    capture_bytes: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    capture_seconds: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    poll_ms: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    offline_after: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    aisles: Option<Vec<u16>>,
    // Shelf.
    #[serde(skip_serializing_if = "Option::is_none")]
    dispatch_window: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    slots: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    base: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    stride: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    clear_finished: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    withdraw: Option<bool>,
    // Crane.
    #[serde(skip_serializing_if = "Option::is_none")]
    wcs_base: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    crane_base: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    inbound_station: Option<Station>,
    #[serde(skip_serializing_if = "Option::is_none")]
    outbound_station: Option<Station>,
    #[serde(skip_serializing_if = "Option::is_none")]
    heartbeat_ms: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    heartbeat_timeout_ms: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    handshake_timeout_ms: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    auto_cancel: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ack: Option<Ack>,
    #[serde(skip_serializing_if = "Option::is_none")]
    planner: Option<Planner>,
    #[serde(skip_serializing_if = "Option::is_none")]
    max_overtaken: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    deadline_margin_s: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    motion: Option<Motion>,
    // Tags.
    #[serde(serialize_with = "tag_map")]
    #[serde(skip_serializing_if = "Option::is_none")]
    tags: Option<TagTable>,
}

fn tag_map<S: serde::Serializer>(tags: &Option<TagTable>, s: S) -> Result<S::Ok, S::Error> {
    tags.as_ref().map(|t| &t.0).serialize(s)
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
            ("planner", self.planner.is_some()),
            ("max_overtaken", self.max_overtaken.is_some()),
            ("deadline_margin_s", self.deadline_margin_s.is_some()),
            ("motion", self.motion.is_some()),
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
        let unit = match self.unit {
            Some(Unit::Number(unit)) => check_unit(protocol, unit)?,
            Some(Unit::Global) if protocol.family() == Family::Mewtocol => GLOBAL_STATION,
            Some(Unit::Global) => return Err(AddressError::GlobalStation(protocol).into()),
            None => protocol.default_unit(),
        };
        let quirks = self.quirks.clone().unwrap_or(quirks);
        let d = LinkTuning::for_replies(protocol.replies(&quirks));
        Ok(LinkConfig {
            protocol,
            address: self.address.clone(),
            unit,
            serial,
            timeout: self.timeout_ms.map_or(timeout, Duration::from_millis),
            retries: self.retries.unwrap_or(DEFAULT_RETRIES),
            quirks,
            tuning: LinkTuning {
                min_timeout: self.min_timeout_ms.map_or(d.min_timeout, Duration::from_millis),
                degraded_window: self.degraded_window.unwrap_or(d.degraded_window),
                degraded_above: self.degraded_above.unwrap_or(d.degraded_above),
                degraded_below: self.degraded_below.unwrap_or(d.degraded_below),
            },
            capture: Limits {
                bytes: self.capture_bytes.unwrap_or(Limits::default().bytes),
                seconds: self.capture_seconds.unwrap_or(Limits::default().seconds),
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
                c.planner = raw.planner.unwrap_or(c.planner);
                c.max_overtaken = raw.max_overtaken.unwrap_or(c.max_overtaken);
                c.deadline_margin_s = raw.deadline_margin_s.unwrap_or(c.deadline_margin_s);
                c.motion = raw.motion.unwrap_or(c.motion);
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

impl RawDevice {
    /// The link's keys, every one set.
    fn with_link(link: &LinkConfig, id: &str, kind: DeviceKind) -> RawDevice {
        RawDevice {
            id: id.to_owned(),
            kind,
            address: link.address.clone(),
            protocol: Some(link.protocol),
            unit: Some(Unit::of(link.protocol, link.unit)),
            serial: link.serial.map(|s| s.to_string()),
            timeout_ms: Some(link.timeout.as_millis() as u64),
            retries: Some(link.retries),
            min_timeout_ms: Some(link.tuning.min_timeout.as_millis() as u64),
            degraded_window: Some(link.tuning.degraded_window),
            degraded_above: Some(link.tuning.degraded_above),
            degraded_below: Some(link.tuning.degraded_below),
            quirks: Some(link.quirks.clone()),
            capture_bytes: Some(link.capture.bytes),
            capture_seconds: Some(link.capture.seconds),
            poll_ms: None,
            offline_after: None,
            aisles: None,
            dispatch_window: None,
            slots: None,
            base: None,
            stride: None,
            clear_finished: None,
            withdraw: None,
            wcs_base: None,
            crane_base: None,
            inbound_station: None,
            outbound_station: None,
            heartbeat_ms: None,
            heartbeat_timeout_ms: None,
            handshake_timeout_ms: None,
            auto_cancel: None,
            ack: None,
            planner: None,
            max_overtaken: None,
            deadline_margin_s: None,
            motion: None,
            tags: None,
        }
    }
}

impl From<&DeviceConfig> for RawDevice {
    fn from(device: &DeviceConfig) -> RawDevice {
        let mut raw = RawDevice::with_link(device.link(), device.id(), device.kind());
        match device {
            DeviceConfig::Shelf(c) => {
                (raw.poll_ms, raw.offline_after) = (Some(c.poll_ms), Some(c.offline_after));
                raw.aisles = Some(c.aisles.clone());
                raw.dispatch_window = Some(c.dispatch_window);
                (raw.slots, raw.base, raw.stride) = (Some(c.slots), Some(c.base.clone()), Some(c.stride));
                (raw.clear_finished, raw.withdraw) = (Some(c.clear_finished), Some(c.withdraw));
            }
            DeviceConfig::Crane(c) => {
                (raw.poll_ms, raw.offline_after) = (Some(c.poll_ms), Some(c.offline_after));
                raw.aisles = Some(c.aisles.clone());
                (raw.wcs_base, raw.crane_base) = (Some(c.wcs_base.clone()), Some(c.crane_base.clone()));
                (raw.inbound_station, raw.outbound_station) =
                    (Some(c.inbound_station), Some(c.outbound_station));
                raw.heartbeat_ms = Some(c.heartbeat_ms);
                raw.heartbeat_timeout_ms = Some(c.heartbeat_timeout_ms);
                raw.handshake_timeout_ms = Some(c.handshake_timeout_ms);
                (raw.auto_cancel, raw.ack) = (Some(c.auto_cancel), Some(c.ack));
                (raw.planner, raw.max_overtaken, raw.motion) =
                    (Some(c.planner), Some(c.max_overtaken), Some(c.motion));
                raw.deadline_margin_s = Some(c.deadline_margin_s);
            }
            DeviceConfig::Tags(c) => {
                (raw.poll_ms, raw.offline_after) = (Some(c.poll_ms), Some(c.offline_after));
                raw.tags = Some(c.tags.clone());
            }
        }
        raw
    }
}
