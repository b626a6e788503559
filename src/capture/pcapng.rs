//! The three pcapng blocks a capture needs (the pcapng specification, IETF
//! draft-ietf-opsawg-pcapng): a Section Header Block, one Interface Description Block and an
//! Enhanced Packet Block per frame, little-endian.
//!
//! Every block is `type(4) total_length(4) body total_length(4)`, its body padded with zeros
//! to 32 bits; options are `code(2) length(2) value`, the value padded to 32 bits, the list
//! closed by `opt_endofopt` (code 0, length 0). A block without options has no list.

/// Section Header Block type.
pub const SHB: u32 = 0x0A0D_0D0A;
/// Interface Description Block type.
pub const IDB: u32 = 0x0000_0001;
/// Enhanced Packet Block type.
pub const EPB: u32 = 0x0000_0006;
/// The byte-order magic readers use to tell the file's endianness.
pub const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;
/// `opt_endofopt`.
pub const OPT_END: u16 = 0;
/// `opt_comment`: UTF-8 text, on any block.
pub const OPT_COMMENT: u16 = 1;
/// `if_name`: the interface's name.
pub const IF_NAME: u16 = 2;
/// `if_tsresol`: timestamp units; 6 is 10^-6 s, microseconds.
pub const IF_TSRESOL: u16 = 9;

/// The longest option value (its length field is 16 bits).
const MAX_OPTION: usize = u16::MAX as usize;

/// Zero bytes that pad `len` to a multiple of 4.
fn padding(len: usize) -> usize {
    (4 - len % 4) % 4
}

/// A whole block: type, length, `body` padded to 32 bits, length again.
fn block(kind: u32, body: &[u8]) -> Vec<u8> {
    let total = 12 + body.len() + padding(body.len());
    let total32 = u32::try_from(total).unwrap_or(u32::MAX);
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(&kind.to_le_bytes());
    out.extend_from_slice(&total32.to_le_bytes());
    out.extend_from_slice(body);
    out.resize(out.len() + padding(body.len()), 0);
    out.extend_from_slice(&total32.to_le_bytes());
    out
}

/// Appends options and the end of the list; nothing when `options` is empty. A value past
/// 65535 bytes is cut there (a UTF-8 text at a character boundary).
fn put_options(out: &mut Vec<u8>, options: &[(u16, &[u8])]) {
    if options.is_empty() {
        return;
    }
    for &(code, value) in options {
        let value = &value[..value.len().min(MAX_OPTION)];
        out.extend_from_slice(&code.to_le_bytes());
        out.extend_from_slice(&(value.len() as u16).to_le_bytes());
        out.extend_from_slice(value);
        out.resize(out.len() + padding(value.len()), 0);
    }
    out.extend_from_slice(&OPT_END.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
}

/// The longest prefix of `text` that fits an option value.
fn option_text(text: &str) -> &str {
    let mut end = text.len().min(MAX_OPTION);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// A Section Header Block: version 1.0, section length unknown (-1), no options.
pub fn section_header() -> Vec<u8> {
    let mut body = Vec::with_capacity(16);
    body.extend_from_slice(&BYTE_ORDER_MAGIC.to_le_bytes());
    body.extend_from_slice(&1u16.to_le_bytes());
    body.extend_from_slice(&0u16.to_le_bytes());
    body.extend_from_slice(&(-1i64).to_le_bytes());
    block(SHB, &body)
}

/// An Interface Description Block: `link_type`, no snap length limit, microsecond
/// timestamps and the interface's `name`.
pub fn interface(link_type: u16, name: &str) -> Vec<u8> {
    let mut body = Vec::with_capacity(32 + name.len());
    body.extend_from_slice(&link_type.to_le_bytes());
    body.extend_from_slice(&0u16.to_le_bytes());
    body.extend_from_slice(&0u32.to_le_bytes());
    put_options(&mut body, &[(IF_TSRESOL, &[6]), (IF_NAME, option_text(name).as_bytes())]);
    block(IDB, &body)
}

/// An Enhanced Packet Block on interface 0: the time in microseconds, the packet's bytes
/// (captured whole) and, unless empty, a comment.
pub fn packet(time_us: u64, data: &[u8], comment: &str) -> Vec<u8> {
    let len = u32::try_from(data.len()).unwrap_or(u32::MAX);
    let mut body = Vec::with_capacity(32 + data.len() + comment.len());
    body.extend_from_slice(&0u32.to_le_bytes());
    body.extend_from_slice(&((time_us >> 32) as u32).to_le_bytes());
    body.extend_from_slice(&(time_us as u32).to_le_bytes());
    body.extend_from_slice(&len.to_le_bytes());
    body.extend_from_slice(&len.to_le_bytes());
    body.extend_from_slice(&data[..len as usize]);
    body.resize(body.len() + padding(data.len()), 0);
    let comment = option_text(comment);
    let options: &[(u16, &[u8])] =
        if comment.is_empty() { &[] } else { &[(OPT_COMMENT, comment.as_bytes())] };
    put_options(&mut body, options);
    block(EPB, &body)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    fn u16_at(b: &[u8], at: usize) -> u16 {
        u16::from_le_bytes(b[at..at + 2].try_into().unwrap())
    }

    /// Type, a total length that is the block's size, a multiple of 4, and repeated last.
    fn check_frame(b: &[u8], kind: u32) {
        assert_eq!(u32_at(b, 0), kind);
        assert_eq!(u32_at(b, 4) as usize, b.len());
        assert_eq!(b.len() % 4, 0);
        assert_eq!(u32_at(b, b.len() - 4) as usize, b.len());
    }

    #[test]
    fn section_header_layout() {
        let b = section_header();
        check_frame(&b, SHB);
        assert_eq!(b.len(), 28);
        assert_eq!(&b[8..12], [0x4D, 0x3C, 0x2B, 0x1A]);
        assert_eq!((u16_at(&b, 12), u16_at(&b, 14)), (1, 0));
        assert_eq!(&b[16..24], [0xFF; 8]);
    }

    #[test]
    fn interface_layout_with_tsresol_and_name() {
        let b = interface(252, "ttyS0");
        check_frame(&b, IDB);
        assert_eq!((u16_at(&b, 8), u16_at(&b, 10), u32_at(&b, 12)), (252, 0, 0));
        // if_tsresol: code 9, length 1, value 6, 3 bytes of padding.
        assert_eq!(&b[16..24], [9, 0, 1, 0, 6, 0, 0, 0]);
        // if_name: code 2, length 5, "ttyS0", 3 bytes of padding.
        assert_eq!(&b[24..28], [2, 0, 5, 0]);
        assert_eq!(&b[28..36], b"ttyS0\0\0\0");
        // opt_endofopt, then the trailing length.
        assert_eq!(&b[36..40], [0, 0, 0, 0]);
        assert_eq!(b.len(), 44);
    }

    #[test]
    fn packet_layout_pads_data_and_comment() {
        let time = 0x0001_0002_0003_0004u64;
        let b = packet(time, &[1, 2, 3, 4, 5], "job 1");
        check_frame(&b, EPB);
        assert_eq!(u32_at(&b, 8), 0, "interface 0");
        assert_eq!((u32_at(&b, 12), u32_at(&b, 16)), (0x0001_0002, 0x0003_0004));
        assert_eq!((u32_at(&b, 20), u32_at(&b, 24)), (5, 5));
        assert_eq!(&b[28..36], [1, 2, 3, 4, 5, 0, 0, 0]);
        assert_eq!(&b[36..40], [1, 0, 5, 0]);
        assert_eq!(&b[40..48], b"job 1\0\0\0");
        assert_eq!(&b[48..52], [0, 0, 0, 0]);
        assert_eq!(b.len(), 56);
    }

    #[test]
    fn a_packet_without_comment_has_no_options() {
        let b = packet(1, &[1, 2, 3, 4], "");
        check_frame(&b, EPB);
        assert_eq!(b.len(), 12 + 20 + 4);
    }

    #[test]
    fn a_long_comment_is_cut_at_a_character_boundary() {
        let text = "é".repeat(40_000);
        let cut = option_text(&text);
        assert_eq!(cut.len(), 65_534);
        let b = packet(1, &[], &text);
        check_frame(&b, EPB);
        assert_eq!(u16_at(&b, 30), 65_534);
    }
}
