//! Contacts (`Y001A`: area, 3 decimal digits of word, 1 hex digit of bit) and the
//! number and word encodings MEWTOCOL-COM commands share.

/// A contact area.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ContactArea {
    /// External inputs.
    X,
    /// External outputs.
    Y,
    /// Internal relays.
    R,
    /// Link relays.
    L,
    /// Timer contacts.
    T,
    /// Counter contacts.
    C,
}

impl ContactArea {
    /// Every contact area.
    pub const ALL: [ContactArea; 6] =
        [ContactArea::X, ContactArea::Y, ContactArea::R, ContactArea::L, ContactArea::T, ContactArea::C];

    /// The area's letter.
    pub fn letter(self) -> u8 {
        match self {
            ContactArea::X => b'X',
            ContactArea::Y => b'Y',
            ContactArea::R => b'R',
            ContactArea::L => b'L',
            ContactArea::T => b'T',
            ContactArea::C => b'C',
        }
    }

    /// The area with this letter (upper case).
    pub fn from_letter(letter: u8) -> Option<ContactArea> {
        ContactArea::ALL.into_iter().find(|a| a.letter() == letter)
    }
}

/// Largest contact word number (3 decimal digits).
pub const MAX_CONTACT_WORD: u16 = 999;
/// Largest word number in RCC/WCC (4 decimal digits).
pub const MAX_WORD: u16 = 9999;
/// Largest DT number in RD/WD (5 decimal digits).
pub const MAX_DT: u32 = 99_999;
/// Most contacts in one RCP or WCP.
pub const MAX_CONTACTS: usize = 8;

/// One contact: area, word number and bit (0..=15).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Contact {
    /// The area.
    pub area: ContactArea,
    /// Word number, 0..=999.
    pub word: u16,
    /// Bit in the word, 0..=15.
    pub bit: u8,
}

impl Contact {
    pub(crate) fn encode(&self, out: &mut Vec<u8>) {
        out.push(self.area.letter());
        out.extend_from_slice(format!("{:03}{:X}", self.word % 1000, self.bit & 15).as_bytes());
    }

    pub(crate) fn decode(b: &[u8]) -> Option<Contact> {
        let area = ContactArea::from_letter(*b.first()?)?;
        let word = decimal(b.get(1..4)?)? as u16;
        let bit = hex_digit(*b.get(4)?)?;
        Some(Contact { area, word, bit })
    }
}

pub(crate) fn decimal(b: &[u8]) -> Option<u32> {
    if b.is_empty() || !b.iter().all(u8::is_ascii_digit) {
        return None;
    }
    std::str::from_utf8(b).ok()?.parse().ok()
}

pub(crate) fn hex_digit(c: u8) -> Option<u8> {
    (c as char).to_digit(16).map(|d| d as u8)
}

/// Appends a word as 4 hex characters, low byte first (0x0001 -> `0100`).
pub fn push_word(out: &mut Vec<u8>, w: u16) {
    out.extend_from_slice(format!("{:02X}{:02X}", w & 0xFF, w >> 8).as_bytes());
}

/// Parses words written low byte first, 4 hex characters each.
pub fn parse_words(b: &[u8]) -> Option<Vec<u16>> {
    if !b.len().is_multiple_of(4) {
        return None;
    }
    b.chunks(4)
        .map(|c| {
            let d: Option<Vec<u16>> = c.iter().map(|&x| hex_digit(x).map(u16::from)).collect();
            let d = d?;
            Some((d[2] << 12) | (d[3] << 8) | (d[0] << 4) | d[1])
        })
        .collect()
}
