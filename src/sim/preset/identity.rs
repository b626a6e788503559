//! A preset's `identity` section: what a simulated PLC says it is, for the requests that ask.
//!
//! ```json
//! {"identity": {"objects": {"VendorName": "ACME", "ProductCode": "X-100", "0x80": "line 4"}}}
//! {"identity": {"model": "R04CPU", "code": "4800"}}
//! ```
//!
//! - Modbus (`rackd sim modbus`): `objects` replaces the simulator's device identification
//!   objects (function 43/14), by the specification's names or by id (`0x80`, `128`). The
//!   basic three (VendorName, ProductCode, MajorMinorRevision) are mandatory in the
//!   specification, so a preset that leaves one out is refused.
//! - MC (`rackd sim mc3e`): `model` (up to 16 ASCII characters) and `code` (hex, as the
//!   manual's table writes it) answer "read CPU model name" (0101), over `--cpu-model` and
//!   `--cpu-code`.
//! - MEWTOCOL and PPI have no such request: an `identity` section there is refused.

use std::collections::BTreeMap;

use anyhow::{Context, bail};
use serde::Deserialize;

use crate::protocols::mc3e::TypeName;
use crate::protocols::modbus::DeviceIdentification;

/// The section as written.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Identity {
    /// Modbus device identification objects, by name or id.
    pub objects: Option<BTreeMap<String, String>>,
    /// MC CPU model name.
    pub model: Option<String>,
    /// MC model code, hexadecimal.
    pub code: Option<String>,
}

const NAMES: [&str; 7] = [
    "VendorName",
    "ProductCode",
    "MajorMinorRevision",
    "VendorUrl",
    "ProductName",
    "ModelName",
    "UserApplicationName",
];

impl Identity {
    /// The Modbus objects, if the section names some (and no MC keys).
    pub fn modbus(&self) -> anyhow::Result<Option<DeviceIdentification>> {
        if self.model.is_some() || self.code.is_some() {
            bail!("identity: `model` and `code` are MC protocol's; a Modbus device takes `objects`");
        }
        let Some(objects) = &self.objects else { return Ok(None) };
        let mut id = DeviceIdentification::empty();
        for (name, value) in objects {
            let object = object_id(name)?;
            id.set(object, value.as_bytes()).map_err(|e| anyhow::anyhow!("identity.objects.{name}: {e}"))?;
        }
        if let Some(missing) =
            NAMES[..3].iter().find(|n| !objects.keys().any(|k| object_id(k).ok() == object_id(n).ok()))
        {
            bail!(
                "identity.objects: {missing} is missing (VendorName, ProductCode and MajorMinorRevision are mandatory)"
            );
        }
        Ok(Some(id))
    }

    /// The MC model name and code, over `fallback` (the command line's).
    pub fn mc3e(&self, fallback: TypeName) -> anyhow::Result<TypeName> {
        if self.objects.is_some() {
            bail!("identity: `objects` are Modbus device identification; an MC CPU takes `model` and `code`");
        }
        let model = self.model.clone().unwrap_or(fallback.model);
        let code = match &self.code {
            Some(text) => u16::from_str_radix(text.trim_start_matches("0x"), 16)
                .with_context(|| format!("identity.code {text:?}: four hex digits such as 0366"))?,
            None => fallback.code,
        };
        TypeName::new(&model, code)
            .with_context(|| format!("identity.model {model:?}: up to 16 printable ASCII characters"))
    }
}

/// An object's id from its name in the specification, or a number (`0x80`, `128`).
fn object_id(name: &str) -> anyhow::Result<u8> {
    if let Some(i) = NAMES.iter().position(|n| n.eq_ignore_ascii_case(name)) {
        return Ok(i as u8);
    }
    let parsed = match name.strip_prefix("0x").or_else(|| name.strip_prefix("0X")) {
        Some(hex) => u8::from_str_radix(hex, 16).ok(),
        None => name.parse().ok(),
    };
    parsed.with_context(|| {
        format!(
            "identity.objects: {name:?} is neither an object name ({}) nor an id 0..255",
            NAMES.join(", ")
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn identity(json: &str) -> Identity {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn objects_by_name_or_id_and_the_basic_three_required() {
        let ok = identity(
            r#"{"objects": {"VendorName": "ACME", "ProductCode": "X", "MajorMinorRevision": "1.0", "0x80": "line 4"}}"#,
        );
        assert!(ok.modbus().unwrap().is_some());
        let missing = identity(r#"{"objects": {"VendorName": "ACME"}}"#).modbus().unwrap_err().to_string();
        assert!(missing.contains("ProductCode is missing"), "{missing}");
        let bad = identity(r#"{"objects": {"Colour": "red"}}"#).modbus().unwrap_err().to_string();
        assert!(bad.contains("neither an object name"), "{bad}");
        assert!(identity(r#"{"model": "R04CPU"}"#).modbus().is_err());
    }

    #[test]
    fn mc_model_and_code_over_the_command_line() {
        let name = identity(r#"{"model": "R04CPU", "code": "4800"}"#).mc3e(TypeName::default()).unwrap();
        assert_eq!((name.model.as_str(), name.code), ("R04CPU", 0x4800));
        let only_code = identity(r#"{"code": "0367"}"#).mc3e(TypeName::default()).unwrap();
        assert_eq!((only_code.model.as_str(), only_code.code), ("Q03UDVCPU", 0x0367));
        assert!(identity(r#"{"model": "A-MODEL-NAME-TOO-LONG"}"#).mc3e(TypeName::default()).is_err());
    }
}
