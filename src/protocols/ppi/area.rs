//! S7-200 memory areas and transport sizes, with their codes in PPI items.

/// An S7-200 memory area and its code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum MemArea {
    /// Sequence control relays (04).
    S,
    /// Special memory (05).
    SM,
    /// Analog inputs (06).
    AI,
    /// Analog outputs (07).
    AQ,
    /// Counters (1E).
    C,
    /// Timers (1F).
    T,
    /// Inputs (81).
    I,
    /// Outputs (82).
    Q,
    /// Flags / bit memory (83).
    M,
    /// Variable memory (84).
    V,
}

impl MemArea {
    /// Every area.
    pub const ALL: [MemArea; 10] = [
        MemArea::S,
        MemArea::SM,
        MemArea::AI,
        MemArea::AQ,
        MemArea::C,
        MemArea::T,
        MemArea::I,
        MemArea::Q,
        MemArea::M,
        MemArea::V,
    ];

    /// The area code in the item (byte 27 of a read request).
    pub fn code(self) -> u8 {
        match self {
            MemArea::S => 0x04,
            MemArea::SM => 0x05,
            MemArea::AI => 0x06,
            MemArea::AQ => 0x07,
            MemArea::C => 0x1E,
            MemArea::T => 0x1F,
            MemArea::I => 0x81,
            MemArea::Q => 0x82,
            MemArea::M => 0x83,
            MemArea::V => 0x84,
        }
    }

    /// The area with this code.
    pub fn from_code(code: u8) -> Option<MemArea> {
        MemArea::ALL.into_iter().find(|a| a.code() == code)
    }

    /// The area's name in Siemens notation.
    pub fn name(self) -> &'static str {
        match self {
            MemArea::S => "S",
            MemArea::SM => "SM",
            MemArea::AI => "AI",
            MemArea::AQ => "AQ",
            MemArea::C => "C",
            MemArea::T => "T",
            MemArea::I => "I",
            MemArea::Q => "Q",
            MemArea::M => "M",
            MemArea::V => "V",
        }
    }
}

/// Transport size of an item.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Size {
    /// One bit (01).
    Bit,
    /// Bytes (02).
    Byte,
    /// 16-bit words (04).
    Word,
    /// 32-bit double words (06).
    DWord,
    /// Counter values (1E), two bytes each.
    Counter,
    /// Timer values (1F), two bytes each.
    Timer,
}

impl Size {
    /// The transport size code.
    pub fn code(self) -> u8 {
        match self {
            Size::Bit => 0x01,
            Size::Byte => 0x02,
            Size::Word => 0x04,
            Size::DWord => 0x06,
            Size::Counter => 0x1E,
            Size::Timer => 0x1F,
        }
    }

    pub(crate) fn from_code(code: u8) -> Option<Size> {
        [Size::Bit, Size::Byte, Size::Word, Size::DWord, Size::Counter, Size::Timer]
            .into_iter()
            .find(|s| s.code() == code)
    }

    /// Data bytes per element.
    pub fn bytes(self) -> usize {
        match self {
            Size::Bit | Size::Byte => 1,
            Size::Word | Size::Counter | Size::Timer => 2,
            Size::DWord => 4,
        }
    }
}
