//! ASCII strings in PLC words, for presets and the control surface: two characters a word
//! (one per item where each item is a byte, as S7 `VB`), the first in the high byte
//! (Modbus, S7: the bytes in memory order) or in the low byte (MC and MEWTOCOL, which keep
//! text low byte first), padded with NUL; reading stops at the first NUL.

use serde_json::Value as Json;

/// The words of an ASCII string padded with NUL to `length` characters.
pub fn text_words(json: &Json, length: u16, per_item: u16, high_first: bool) -> anyhow::Result<Vec<u16>> {
    let text = json.as_str().ok_or_else(|| anyhow::anyhow!("a string takes a JSON string, not {json}"))?;
    anyhow::ensure!(text.is_ascii(), "{text:?} is not ASCII");
    anyhow::ensure!(text.len() <= length as usize, "{text:?} is longer than length {length}");
    let mut bytes = text.as_bytes().to_vec();
    bytes.resize(length.div_ceil(per_item) as usize * per_item as usize, 0);
    Ok(match (per_item, high_first) {
        (1, _) => bytes.iter().map(|&b| b.into()).collect(),
        (_, true) => bytes.chunks(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect(),
        (_, false) => bytes.chunks(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect(),
    })
}

/// The string in words, up to the first NUL; bytes beyond ASCII show as U+FFFD.
pub fn text_of(words: &[u16], per_item: u16, high_first: bool) -> String {
    let bytes: Vec<u8> = match (per_item, high_first) {
        (1, _) => words.iter().map(|&w| w as u8).collect(),
        (_, true) => words.iter().flat_map(|w| w.to_be_bytes()).collect(),
        (_, false) => words.iter().flat_map(|w| w.to_le_bytes()).collect(),
    };
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    bytes[..end].iter().map(|&b| if b.is_ascii() { b as char } else { '\u{FFFD}' }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_orders_and_padding() {
        let abc = Json::from("ABC");
        assert_eq!(text_words(&abc, 4, 2, true).unwrap(), [0x4142, 0x4300]);
        assert_eq!(text_words(&abc, 3, 2, false).unwrap(), [0x4241, 0x0043]);
        assert_eq!(text_words(&abc, 4, 1, true).unwrap(), [0x41, 0x42, 0x43, 0]);
        assert_eq!(text_of(&[0x4142, 0x4300, 0x4444], 2, true), "ABC");
        assert_eq!(text_of(&[0x4241, 0x0043], 2, false), "ABC");
        assert_eq!(text_of(&[0x41, 0xC3], 1, true), "A\u{FFFD}");
        assert!(text_words(&Json::from("é"), 4, 2, true).is_err());
        assert!(text_words(&Json::from(5), 4, 2, true).is_err());
        assert!(text_words(&abc, 2, 2, true).is_err());
    }
}
