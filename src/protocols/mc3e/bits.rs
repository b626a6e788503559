//! The packing of bit values in binary bit-unit requests and replies: two points per byte,
//! the first in the high nibble, `1` for ON.

/// Bytes needed for `count` bits in bit units.
pub fn bit_bytes(count: usize) -> usize {
    count.div_ceil(2)
}

/// Packs bits two per byte, first point in the high nibble, `1` for ON (binary bit units).
pub fn pack_bits(bits: &[bool], out: &mut Vec<u8>) {
    for pair in bits.chunks(2) {
        let hi = u8::from(pair[0]) << 4;
        let lo = pair.get(1).map_or(0, |b| u8::from(*b));
        out.push(hi | lo);
    }
}

/// Unpacks `count` bits; `None` if `bytes` is not exactly [`bit_bytes`]`(count)` long or a
/// nibble is neither 0 nor 1.
pub fn unpack_bits(bytes: &[u8], count: usize) -> Option<Vec<bool>> {
    if bytes.len() != bit_bytes(count) {
        return None;
    }
    let mut bits = Vec::with_capacity(count);
    for (i, byte) in bytes.iter().enumerate() {
        let (hi, lo) = (byte >> 4, byte & 0x0F);
        if hi > 1 || lo > 1 {
            return None;
        }
        bits.push(hi == 1);
        if 2 * i + 1 < count {
            bits.push(lo == 1);
        }
    }
    Some(bits)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_pack_high_nibble_first() {
        // The MC Protocol Reference Manual's (SH-080008) bit-unit read example: M100..M107 =
        // 0,0,0,1,0,0,1,1 is `00 01 00 11`.
        let bits = [false, false, false, true, false, false, true, true];
        let mut out = Vec::new();
        pack_bits(&bits, &mut out);
        assert_eq!(out, [0x00, 0x01, 0x00, 0x11]);
        assert_eq!(unpack_bits(&out, 8).unwrap(), bits);
        let mut odd = Vec::new();
        pack_bits(&[true, false, true], &mut odd);
        assert_eq!(odd, [0x10, 0x10]);
        assert_eq!(unpack_bits(&odd, 3).unwrap(), [true, false, true]);
    }

    #[test]
    fn unpack_rejects_bad_nibbles_and_lengths() {
        assert_eq!(unpack_bits(&[0x20], 2), None);
        assert_eq!(unpack_bits(&[0x01], 3), None);
        assert_eq!(unpack_bits(&[], 0), Some(vec![]));
    }
}
