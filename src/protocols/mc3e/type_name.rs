//! The answer to "read CPU model name" (command 0101): 16 ASCII characters of model name,
//! padded with spaces, then the 2-byte model code (little-endian).
//!
//! The simulator's default is a Q03UDVCPU with model code 0x0366, as plc-comm-slmp-rust's
//! model-family tests pair them (the manual's model code table lists the Q/L codes). Layout
//! as pymcprotocol's `read_cputype` reads it.
//! On decode, trailing spaces and NULs are trimmed; a name that is not ASCII is malformed.

use crate::protocols::PlcError;

/// A CPU's model name and model code.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TypeName {
    /// The model name, trimmed (`Q03UDVCPU`).
    pub model: String,
    /// The model code (0x0366 for a Q03UDVCPU).
    pub code: u16,
}

impl Default for TypeName {
    /// A Q03UDVCPU, model code 0x0366.
    fn default() -> Self {
        TypeName { model: "Q03UDVCPU".to_owned(), code: 0x0366 }
    }
}

impl TypeName {
    /// Bytes of the reply data: 16 of name, 2 of code.
    pub const LEN: usize = 18;
    /// Characters of the model name field.
    pub const NAME_LEN: usize = 16;

    /// A type name; `None` if the model is not printable ASCII or longer than 16 characters.
    pub fn new(model: &str, code: u16) -> Option<TypeName> {
        let ok = model.len() <= Self::NAME_LEN && model.bytes().all(|b| b.is_ascii_graphic() || b == b' ');
        ok.then(|| TypeName { model: model.trim_end().to_owned(), code })
    }

    /// The reply data: the name padded with spaces to 16 bytes, then the code.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = format!("{:<16}", self.model).into_bytes();
        out.truncate(Self::NAME_LEN);
        out.extend_from_slice(&self.code.to_le_bytes());
        out
    }

    /// Reads the reply data.
    pub fn decode(data: &[u8]) -> Result<TypeName, PlcError> {
        let (Some(name), Some(&[c0, c1])) = (data.get(..Self::NAME_LEN), data.get(Self::NAME_LEN..)) else {
            return Err(PlcError::Malformed("type name reply is not 18 bytes"));
        };
        let name = std::str::from_utf8(name)
            .ok()
            .filter(|n| n.is_ascii())
            .ok_or(PlcError::Malformed("type name is not ASCII"))?;
        Ok(TypeName {
            model: name.trim_end_matches([' ', '\0']).to_owned(),
            code: u16::from_le_bytes([c0, c1]),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn q03udv_round_trip() {
        let bytes = TypeName::default().encode();
        let mut expect = b"Q03UDVCPU       ".to_vec();
        expect.extend_from_slice(&[0x66, 0x03]);
        assert_eq!(bytes, expect);
        assert_eq!(TypeName::decode(&bytes).unwrap(), TypeName::default());
    }

    #[test]
    fn trims_nuls_and_refuses_bad_data() {
        let mut bytes = b"L26CPU-BT\0\0\0\0\0\0\0".to_vec();
        bytes.extend_from_slice(&[0x34, 0x12]);
        assert_eq!(TypeName::decode(&bytes).unwrap(), TypeName { model: "L26CPU-BT".into(), code: 0x1234 });
        assert!(TypeName::decode(&bytes[..17]).is_err());
        bytes[0] = 0xFF;
        assert!(TypeName::decode(&bytes).is_err());
        assert!(TypeName::new("A-VERY-LONG-MODEL-NAME", 1).is_none());
        assert_eq!(TypeName::new("R04CPU", 0x4800).unwrap().model, "R04CPU");
    }
}
