//! One poll cycle: every planned read, each tag's value from it, and all outcomes recorded
//! in the device status under one lock, so a watcher never sees half a cycle.

use std::sync::Arc;

use super::{TagDevice, link_failed};
use crate::protocols::{Address, PlcError};
use crate::wire::tags::TagFault;
use crate::wire::tags::codec::TagValue;
use crate::wire::tags::spec::TagSpec;

/// What one read returned.
pub(super) enum Raw {
    /// From `read_bits`.
    Bits(Vec<bool>),
    /// From `read_words`.
    Words(Vec<u16>),
}

impl Raw {
    /// The value of `spec`, whose first item is at `offset` in this read.
    pub(super) fn value_of(&self, spec: &TagSpec, offset: usize) -> Result<TagValue, TagFault> {
        let range = offset..offset + spec.count() as usize;
        Ok(match self {
            Raw::Bits(bits) => spec.from_bits(bits.get(range).ok_or(TagFault::Short)?)?,
            Raw::Words(words) => spec.from_words(words.get(range).ok_or(TagFault::Short)?)?,
        })
    }
}

impl TagDevice {
    /// Reads every tag once and records the outcomes.
    pub(super) async fn poll(&mut self) {
        let mut outcomes = Vec::with_capacity(self.specs.len());
        let mut link_down: Option<Arc<PlcError>> = None;
        for g in 0..self.groups.len() {
            let group = self.groups[g].clone();
            if let Some(e) = &link_down {
                outcomes.extend(group.members.iter().map(|&(i, _)| (i, Err(TagFault::NotRead(e.clone())))));
                continue;
            }
            match self.read(group.bits, &group.at, group.count).await {
                Ok(raw) => {
                    let specs = &self.specs;
                    outcomes.extend(
                        group.members.iter().map(|&(i, offset)| (i, raw.value_of(&specs[i], offset))),
                    );
                }
                Err(e) => {
                    let failed = link_failed(&e);
                    let e = Arc::new(e);
                    outcomes.extend(group.members.iter().map(|&(i, _)| (i, Err(TagFault::Plc(e.clone())))));
                    if failed {
                        link_down = Some(e);
                    }
                }
            }
        }
        self.record(outcomes);
    }

    /// Reads bits or words, keeping the contact bookkeeping.
    pub(super) async fn read(&mut self, bits: bool, at: &Address, count: u16) -> Result<Raw, PlcError> {
        let result = match bits {
            true => self.plc.read_bits(at, count).await.map(Raw::Bits),
            false => self.plc.read_words(at, count).await.map(Raw::Words),
        };
        self.contact(&result);
        result
    }

    /// Records read outcomes (tag index, value or why not) in the device status.
    pub(super) fn record(&mut self, outcomes: Vec<(usize, Result<TagValue, TagFault>)>) {
        let now = crate::domain::time::from_ms(crate::domain::time::now_ms());
        let specs = &self.specs;
        self.status.update_marked(|status| {
            let Some(tags) = status.tags.as_mut() else { return false };
            let mut changed = false;
            for (i, outcome) in outcomes {
                if let Some(tag) = tags.get_mut(&specs[i].name) {
                    changed |= tag.settle(outcome, now);
                }
            }
            changed
        });
    }
}
