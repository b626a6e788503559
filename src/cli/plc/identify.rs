//! `rackd plc identify`: what the PLC says it is, where its protocol has a request for it.
//!
//! - Modbus: Read Device Identification (function 43, MEI type 14), the basic, regular or
//!   extended objects (`--category`), or one object (`--object N`), as `NAME VALUE` lines.
//! - MC protocol: "read CPU model name" (command 0101): `model` and `code` (hexadecimal, as
//!   the manual's table writes it).
//! - MEWTOCOL and PPI: refused, naming what to use instead. MEWTOCOL's "read the status" (RT)
//!   and the S7's system status lists are not spoken by rackd's clients.

use anyhow::{Context, anyhow, bail};

use super::capture::Capture;
use super::hints;
use crate::protocols::PlcMemory;
use crate::protocols::link::{self, LinkConfig, LinkError};
use crate::protocols::modbus::{DeviceObject, ObjectId, ReadDeviceIdCode};
use crate::protocols::protocol::Family;

/// Which Modbus identification objects to ask for.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Category {
    /// VendorName, ProductCode, MajorMinorRevision (every device that answers has them).
    Basic,
    /// The basic objects and VendorUrl, ProductName, ModelName, UserApplicationName.
    Regular,
    /// Every object, including the device's own (0x80..0xFF).
    Extended,
}

impl From<Category> for ReadDeviceIdCode {
    fn from(c: Category) -> Self {
        match c {
            Category::Basic => ReadDeviceIdCode::Basic,
            Category::Regular => ReadDeviceIdCode::Regular,
            Category::Extended => ReadDeviceIdCode::Extended,
        }
    }
}

/// What the PLC says it is, as `(name, value)` pairs in the order it answered them. With
/// `capture`, the link's recorder is handed to it.
pub async fn identify(
    link: &LinkConfig,
    category: Category,
    object: Option<u8>,
    capture: Option<&Capture>,
) -> anyhow::Result<Vec<(String, String)>> {
    let keep = |recorder| {
        if let Some(c) = capture {
            c.keep(recorder);
        }
    };
    let explain = |e: LinkError| match e {
        LinkError::Plc(e) => anyhow!(hints::explain(&e, link.protocol)),
        other => anyhow!(other),
    };
    match link.protocol.family() {
        Family::Modbus => {
            let client = link::connect_modbus(link).await.map_err(explain)?;
            keep(client.recorder());
            let objects = match object {
                Some(id) => client.read_device_object(id).await.map(|o| vec![o]),
                None => client.read_device_identification(category.into()).await,
            };
            let objects = objects.map_err(|e| explain(LinkError::Plc(e))).with_context(|| {
                "read device identification (function 43/14); devices that do not offer it answer \
                 exception 01"
            })?;
            Ok(objects.iter().map(named).collect())
        }
        Family::Mc3e => {
            let client = link::connect_mc3e(link).map_err(explain)?;
            keep(client.recorder());
            let name = client
                .read_type_name()
                .await
                .map_err(|e| explain(LinkError::Plc(e)))
                .context("read CPU model name (command 0101)")?;
            Ok(vec![("model".into(), name.model), ("code".into(), format!("{:04X}", name.code))])
        }
        Family::Mewtocol | Family::Ppi => bail!(
            "{} has no identification request that rackd speaks; read the PLC's system registers \
             with `read` instead",
            link.protocol
        ),
    }
}

/// An object as `NAME VALUE`: the specification's name, or `object 0xNN`.
fn named(object: &DeviceObject) -> (String, String) {
    let name = match object.kind() {
        ObjectId::VendorName => "VendorName".to_owned(),
        ObjectId::ProductCode => "ProductCode".to_owned(),
        ObjectId::MajorMinorRevision => "MajorMinorRevision".to_owned(),
        ObjectId::VendorUrl => "VendorUrl".to_owned(),
        ObjectId::ProductName => "ProductName".to_owned(),
        ObjectId::ModelName => "ModelName".to_owned(),
        ObjectId::UserApplicationName => "UserApplicationName".to_owned(),
        ObjectId::Reserved(id) | ObjectId::Extended(id) => format!("object 0x{id:02X}"),
    };
    (name, object.text())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objects_are_named_as_the_specification_names_them() {
        let vendor = DeviceObject { id: 0, value: b"rackd".to_vec() };
        assert_eq!(named(&vendor), ("VendorName".into(), "rackd".into()));
        let own = DeviceObject { id: 0x81, value: b"x".to_vec() };
        assert_eq!(named(&own).0, "object 0x81");
    }
}
