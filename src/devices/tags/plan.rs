//! Reading many tags in few requests: tags whose items touch or overlap in one area are
//! read together.
//!
//! Only tags that adjoin or overlap share a read; a gap between two tags starts a new one,
//! even a gap of one word, because a PLC may refuse a read that covers an address it does
//! not have, and then every tag of the read would turn bad for no fault of its own.

use crate::protocols::Address;
use crate::wire::tags::spec::{Place, TagSpec};

/// Most words in one read (one Modbus request holds 125).
pub const MAX_WORDS: u16 = 120;

/// Most bits in one read.
pub const MAX_BITS: u16 = 256;

/// One read and the tags it serves.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Group {
    /// The first bit or word read.
    pub at: Address,
    /// Bits or words read.
    pub count: u16,
    /// A bit read (`read_bits`) rather than a word read.
    pub bits: bool,
    /// The tags served: (index in the spec list, offset of its first item in the read).
    pub members: Vec<(usize, usize)>,
}

/// The reads that cover every tag of `specs`, in address order.
pub fn plan(specs: &[TagSpec]) -> Vec<Group> {
    let mut order: Vec<usize> = (0..specs.len()).collect();
    order.sort_by(|&a, &b| {
        let key = |s: &TagSpec| (s.place != Place::Bit, s.at.area.clone(), s.at.index, u16::MAX - s.count());
        key(&specs[a]).cmp(&key(&specs[b]))
    });
    let mut groups: Vec<Group> = Vec::new();
    for i in order {
        let spec = &specs[i];
        let bits = spec.place == Place::Bit;
        if let Some(group) = groups.last_mut()
            && group.bits == bits
            && group.at.area == spec.at.area
            && let Some(offset) = join(group, spec)
        {
            group.members.push((i, offset));
            continue;
        }
        groups.push(Group { at: spec.at.clone(), count: spec.count(), bits, members: vec![(i, 0)] });
    }
    groups
}

/// Extends `group` to cover `spec` (which does not start before it) if they adjoin or
/// overlap; the tag's item offset in the read.
fn join(group: &mut Group, spec: &TagSpec) -> Option<usize> {
    let step = if group.bits { 1 } else { spec.step.max(1) } as u64;
    let start = group.at.index as u64;
    let from = spec.at.index as u64;
    // An S7 word at an odd byte offset does not line up with the words read from an even one.
    if from < start || !(from - start).is_multiple_of(step) {
        return None;
    }
    let end = start + step * group.count as u64;
    let spec_end = from + step * spec.count() as u64;
    let covered = spec_end <= end;
    // S7 double words are read in whole pairs: only one that starts where the read ends
    // keeps the count even.
    let adjoins = if spec.double_words { from == end } else { from <= end };
    let count = (end.max(spec_end) - start) / step;
    let max = if group.bits { MAX_BITS } else { MAX_WORDS };
    if !(covered || adjoins) || count > max as u64 {
        return None;
    }
    group.count = count as u16;
    Some(((from - start) / step) as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::tags::TagDef;
    use crate::wire::tags::TagType;

    fn specs(protocol: &str, tags: &[(&str, Option<TagType>)]) -> Vec<TagSpec> {
        tags.iter()
            .enumerate()
            .map(|(i, (address, ty))| {
                let def = TagDef { ty: *ty, ..TagDef::at(address) };
                TagSpec::resolve(protocol.parse().unwrap(), &format!("t{i}"), &def).unwrap()
            })
            .collect()
    }

    fn reads(groups: &[Group]) -> Vec<(String, u32, u16)> {
        groups.iter().map(|g| (g.at.area.to_string(), g.at.index, g.count)).collect()
    }

    #[test]
    fn adjoining_and_overlapping_words_share_a_read() {
        let s = specs(
            "modbus-tcp",
            &[
                ("4x102", Some(TagType::F32)),
                ("4x100", None),
                ("4x101.3", None),
                ("4x101", None),
                ("4x106", None),
                ("3x100", None),
                ("0x1", None),
                ("0x2", None),
                ("0x4", None),
            ],
        );
        let groups = plan(&s);
        assert_eq!(
            reads(&groups),
            [
                ("0X".into(), 1, 2),
                ("0X".into(), 4, 1),
                ("3X".into(), 100, 1),
                ("4X".into(), 100, 4),
                ("4X".into(), 106, 1)
            ]
        );
        let words = &groups[3];
        assert!(!words.bits && groups[0].bits);
        let mut members = words.members.clone();
        members.sort();
        assert_eq!(members, [(0, 2), (1, 0), (2, 1), (3, 1)]);
    }

    #[test]
    fn s7_words_step_two_bytes_and_double_words_stay_whole() {
        let s = specs(
            "ppi-tcp",
            &[
                ("VW100", None),
                ("VW102", None),
                ("VW105", None),
                ("VW104", None),
                ("VD4", None),
                ("VD8", None),
                ("VD12", None),
                ("VD6", None),
            ],
        );
        // VD6 overlaps VD4 and VD8 by half: reading it with them would give an odd count.
        assert_eq!(
            reads(&plan(&s)),
            [
                ("VD".into(), 4, 2),
                ("VD".into(), 6, 2),
                ("VD".into(), 8, 4),
                ("VW".into(), 100, 3),
                ("VW".into(), 105, 1),
            ]
        );
    }

    #[test]
    fn reads_are_bounded() {
        let addresses: Vec<String> = (0..300).map(|i| format!("4x{i}")).collect();
        let tags: Vec<(&str, Option<TagType>)> = addresses.iter().map(|a| (a.as_str(), None)).collect();
        let groups = plan(&specs("modbus-tcp", &tags));
        assert_eq!(groups.iter().map(|g| g.count).collect::<Vec<_>>(), [120, 120, 60]);
        assert_eq!(groups.iter().map(|g| g.members.len()).sum::<usize>(), 300);
    }
}
