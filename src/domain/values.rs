//! Small validated values: priority and barcode.

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Job priority, 0..=20, lower first; 0 jumps the queue. The default is 10.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(try_from = "i64", into = "u8")]
pub struct Priority(u8);

impl Priority {
    /// The most urgent priority.
    pub const MAX_URGENT: u8 = 0;
    /// The least urgent priority.
    pub const LEAST_URGENT: u8 = 20;
    /// The priority of a job that names none.
    pub const DEFAULT: Priority = Priority(10);

    /// The numeric value, 0..=20.
    pub fn get(self) -> u8 {
        self.0
    }
}

impl TryFrom<i64> for Priority {
    type Error = Invalid;
    fn try_from(value: i64) -> Result<Self, Invalid> {
        if (0..=Self::LEAST_URGENT as i64).contains(&value) {
            Ok(Priority(value as u8))
        } else {
            Err(Invalid(format!("priority must be 0..=20 (lower first), got {value}")))
        }
    }
}

impl From<Priority> for u8 {
    fn from(p: Priority) -> u8 {
        p.0
    }
}

impl Default for Priority {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A box barcode: 1..=20 printable ASCII characters (the shelf PLC's slot holds 20).
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Barcode(String);

impl Barcode {
    /// The longest barcode a task slot can carry.
    pub const MAX_LEN: usize = 20;

    /// The barcode's text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl TryFrom<String> for Barcode {
    type Error = Invalid;
    fn try_from(text: String) -> Result<Self, Invalid> {
        if text.is_empty() || text.len() > Self::MAX_LEN {
            return Err(Invalid(format!("barcode must be 1..=20 characters, got {}", text.chars().count())));
        }
        if let Some(c) = text.chars().find(|c| !(' '..='~').contains(c)) {
            return Err(Invalid(format!("barcode must be printable ASCII, found {c:?}")));
        }
        Ok(Barcode(text))
    }
}

impl From<Barcode> for String {
    fn from(b: Barcode) -> String {
        b.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn priority_bounds() {
        assert_eq!(Priority::try_from(0).unwrap().get(), 0);
        assert_eq!(Priority::try_from(20).unwrap().get(), 20);
        assert!(Priority::try_from(21).is_err());
        assert!(Priority::try_from(-1).is_err());
        assert_eq!(Priority::default().get(), 10);
    }

    #[test]
    fn barcode_rules() {
        assert!(Barcode::try_from("BOX-0001".to_string()).is_ok());
        assert!(Barcode::try_from("A".repeat(20)).is_ok());
        assert!(Barcode::try_from("A".repeat(21)).is_err());
        assert!(Barcode::try_from(String::new()).is_err());
        assert!(Barcode::try_from("tab\there".to_string()).is_err());
        assert!(Barcode::try_from("caf\u{e9}".to_string()).is_err());
    }
}
