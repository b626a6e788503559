//! Read Device Identification: function 0x2B (encapsulated interface) with MEI type 0x0E,
//! Modbus Application Protocol Specification V1.1b3, section 6.21.
//!
//! A device holds objects (id 0..=255, each a byte string): basic 0..=2 (vendor name,
//! product code, revision, mandatory), regular 3..=0x7F (vendor URL, product name, model
//! name, user application name, then reserved ids), extended 0x80..=0xFF (device specific).
//! A request names a read device id code (01 basic, 02 regular, 03 extended stream access
//! from an object id; 04 one object) and the reply carries as many objects as fit in one
//! PDU, with "more follows" = FF and the next object id when the rest needs another request.
//!
//! Decisions where the specification leaves room:
//! - **Server objects** ([`DeviceIdentification`], on the server's options) are rackd's
//!   defaults unless set; a value longer than [`MAX_OBJECT_LEN`] (what fits one reply) is
//!   refused when set, so every object can be sent.
//! - **Stream access from an unknown object id** restarts at the category's first object,
//!   as section 6.21 prescribes; individual access (04) to an unknown id is exception 02,
//!   a read device id code outside 01..=04 exception 03, another MEI type exception 01.
//! - **Conformity level**: 0x80 (individual access) plus the highest category the device
//!   has objects in (0x81, 0x82 or 0x83).
//! - **Client**: a reply whose object lengths run past the PDU, whose MEI type or read
//!   device id code is not the request's, or whose "more follows" is neither 00 nor FF is
//!   malformed (a typed [`super::decode::DecodeError`]); when paging, a next object id that
//!   does not move forward is malformed too, so the loop ends after 256 requests at most.
//!
//! The objects and the paging are here; the bytes of a request and a reply are encoded with
//! every other PDU's ([`super::pdu`]) and decoded with them ([`super::decode`]).

use std::collections::BTreeMap;

use super::exception::Exception;

/// The MEI type of Read Device Identification.
pub const MEI_DEVICE_ID: u8 = 0x0E;
/// Most bytes of one object value: a PDU of 253 bytes less the 7-byte reply header and the
/// object's id and length.
pub const MAX_OBJECT_LEN: usize = 244;
/// Bytes of a reply PDU before its objects: function, MEI type, code, conformity level,
/// more follows, next object id, number of objects.
pub(super) const HEADER_LEN: usize = 7;
/// Largest PDU.
pub(super) const MAX_PDU: usize = 253;

/// The read device id code: which objects a request asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum ReadDeviceIdCode {
    /// 01: the basic objects 0..=2, as a stream.
    Basic = 1,
    /// 02: the basic and regular objects 0..=0x7F, as a stream.
    Regular = 2,
    /// 03: every object 0..=0xFF, as a stream.
    Extended = 3,
    /// 04: one object.
    Individual = 4,
}

impl ReadDeviceIdCode {
    /// The code for a byte, if it is one.
    pub fn from_byte(b: u8) -> Option<Self> {
        match b {
            1 => Some(Self::Basic),
            2 => Some(Self::Regular),
            3 => Some(Self::Extended),
            4 => Some(Self::Individual),
            _ => None,
        }
    }

    /// The last object id a stream access of this code covers.
    fn last_id(self) -> u8 {
        match self {
            Self::Basic => 0x02,
            Self::Regular => 0x7F,
            Self::Extended | Self::Individual => 0xFF,
        }
    }
}

/// What an object id means (section 6.21, table of objects).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjectId {
    /// 0x00 VendorName.
    VendorName,
    /// 0x01 ProductCode.
    ProductCode,
    /// 0x02 MajorMinorRevision.
    MajorMinorRevision,
    /// 0x03 VendorUrl.
    VendorUrl,
    /// 0x04 ProductName.
    ProductName,
    /// 0x05 ModelName.
    ModelName,
    /// 0x06 UserApplicationName.
    UserApplicationName,
    /// 0x07..=0x7F: reserved by the specification.
    Reserved(u8),
    /// 0x80..=0xFF: device dependent (extended).
    Extended(u8),
}

impl From<u8> for ObjectId {
    fn from(id: u8) -> Self {
        match id {
            0 => ObjectId::VendorName,
            1 => ObjectId::ProductCode,
            2 => ObjectId::MajorMinorRevision,
            3 => ObjectId::VendorUrl,
            4 => ObjectId::ProductName,
            5 => ObjectId::ModelName,
            6 => ObjectId::UserApplicationName,
            0x07..=0x7F => ObjectId::Reserved(id),
            _ => ObjectId::Extended(id),
        }
    }
}

/// One object as read from a device.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceObject {
    /// The object id on the wire.
    pub id: u8,
    /// The value: usually ASCII text, but the specification allows any bytes.
    pub value: Vec<u8>,
}

impl DeviceObject {
    /// What the id means.
    pub fn kind(&self) -> ObjectId {
        ObjectId::from(self.id)
    }

    /// The value as text (invalid UTF-8 replaced).
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.value).into_owned()
    }
}

/// One reply to a Read Device Identification request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceIdPage {
    /// The read device id code echoed.
    pub code: ReadDeviceIdCode,
    /// The device's conformity level (0x01..=0x03, plus 0x80 with individual access).
    pub conformity: u8,
    /// Where the next request starts, when more objects follow.
    pub next: Option<u8>,
    /// The objects in this reply.
    pub objects: Vec<DeviceObject>,
}

/// Why an object cannot be set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("device identification object {id:#04X} is {len} bytes; at most {MAX_OBJECT_LEN} fit in a reply")]
pub struct ObjectTooLong {
    /// The object id.
    pub id: u8,
    /// Its length.
    pub len: usize,
}

/// The objects a server answers Read Device Identification from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceIdentification {
    objects: BTreeMap<u8, Vec<u8>>,
}

impl Default for DeviceIdentification {
    /// rackd's simulator: vendor "rackd", product code "rackd-sim-modbus", revision the
    /// crate's version, product name "rackd Modbus simulator", model name "sim modbus".
    fn default() -> Self {
        let mut objects = BTreeMap::new();
        objects.insert(0x00, b"rackd".to_vec());
        objects.insert(0x01, b"rackd-sim-modbus".to_vec());
        objects.insert(0x02, env!("CARGO_PKG_VERSION").as_bytes().to_vec());
        objects.insert(0x04, b"rackd Modbus simulator".to_vec());
        objects.insert(0x05, b"sim modbus".to_vec());
        DeviceIdentification { objects }
    }
}

impl DeviceIdentification {
    /// No objects at all (a device that has none answers every stream access empty).
    pub fn empty() -> Self {
        DeviceIdentification { objects: BTreeMap::new() }
    }

    /// Sets object `id` to `value`.
    pub fn set(&mut self, id: u8, value: impl Into<Vec<u8>>) -> Result<(), ObjectTooLong> {
        let value = value.into();
        if value.len() > MAX_OBJECT_LEN {
            return Err(ObjectTooLong { id, len: value.len() });
        }
        self.objects.insert(id, value);
        Ok(())
    }

    /// The value of object `id`, if set.
    pub fn get(&self, id: u8) -> Option<&[u8]> {
        self.objects.get(&id).map(Vec::as_slice)
    }

    fn conformity(&self) -> u8 {
        let highest = match self.objects.keys().next_back() {
            Some(0x80..) => 0x03,
            Some(0x03..) => 0x02,
            _ => 0x01,
        };
        0x80 | highest
    }

    /// The reply to a request of `code` from object `first`, or exception 02 for an unknown
    /// object on individual access (a bad read device id code, 03, does not decode).
    pub fn answer(&self, code: ReadDeviceIdCode, first: u8) -> Result<DeviceIdPage, Exception> {
        let conformity = self.conformity();
        if code == ReadDeviceIdCode::Individual {
            let value = self.objects.get(&first).ok_or(Exception::ILLEGAL_DATA_ADDRESS)?;
            let objects = vec![DeviceObject { id: first, value: value.clone() }];
            return Ok(DeviceIdPage { code, conformity, next: None, objects });
        }
        let last = code.last_id();
        let first = if self.objects.contains_key(&first) && first <= last { first } else { 0 };
        let (mut objects, mut size, mut next) = (Vec::new(), HEADER_LEN, None);
        for (&id, value) in self.objects.range(first..=last) {
            if size + 2 + value.len() > MAX_PDU {
                next = Some(id);
                break;
            }
            size += 2 + value.len();
            objects.push(DeviceObject { id, value: value.clone() });
        }
        Ok(DeviceIdPage { code, conformity, next, objects })
    }
}

#[cfg(test)]
#[path = "device_id_tests.rs"]
mod tests;
