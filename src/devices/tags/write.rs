//! Performing a checked write in the device task: refuse while offline, write the bit or
//! words (a bit of a word read-modify-write), read the tag back and answer it as read.

use super::TagDevice;
use super::handle::{WriteError, WriteRequest};
use super::poll::Raw;
use crate::protocols::{Address, PlcError};
use crate::wire::tags::Tag;
use crate::wire::tags::codec::{self, TagValue, ValueError};
use crate::wire::tags::spec::Place;

impl TagDevice {
    /// Performs one write request and answers it.
    pub(super) async fn write(&mut self, request: WriteRequest) {
        let name = self.specs[request.tag].name.clone();
        if request.reply.is_closed() {
            // The caller stopped waiting: a write arriving later would surprise whoever
            // asked, so it is not made at all.
            tracing::warn!(tag = %name, "tag write dropped: its caller gave up");
            return;
        }
        let result = self.perform(request.tag, request.value).await;
        match &result {
            Ok(tag) => {
                let read_back = tag.status.value.map(|v| v.to_string()).unwrap_or_default();
                tracing::info!(tag = %name, asked = %request.value, %read_back, "tag written");
            }
            Err(e) => tracing::warn!(tag = %name, error = %e, "tag write failed"),
        }
        let _ = request.reply.send(result);
    }

    async fn perform(&mut self, index: usize, value: TagValue) -> Result<Tag, WriteError> {
        {
            let status = self.status.get();
            if !status.online {
                let why = status.last_error.clone().unwrap_or_else(|| "not reached yet".into());
                return Err(WriteError::Offline(why));
            }
        }
        let spec = self.specs[index].clone();
        let mismatch = || WriteError::Invalid {
            tag: spec.name.clone(),
            error: ValueError::Type {
                ty: spec.ty.as_str(),
                expected: "a value of its type",
                got: value.to_string(),
            },
        };
        match (spec.place, value) {
            (Place::Bit, TagValue::Bool(on)) => self.write_bits(&spec.at, &[on]).await?,
            (Place::WordBit(bit), TagValue::Bool(on)) => {
                let word = match self.read(false, &spec.at, 1).await.map_err(WriteError::Plc)? {
                    Raw::Words(w) if w.len() == 1 => w[0],
                    _ => return Err(WriteError::Plc(PlcError::Malformed("no word in the reply"))),
                };
                self.write_words(&spec.at, &[codec::with_bit(word, bit, on)]).await?
            }
            (Place::Words, value) => {
                let words = codec::encode(spec.ty, spec.order, value).map_err(|_| mismatch())?;
                self.write_words(&spec.at, &words).await?
            }
            _ => return Err(mismatch()),
        }
        let bits = spec.place == Place::Bit;
        let raw = self.read(bits, &spec.at, spec.count()).await.map_err(WriteError::ReadBack)?;
        self.record(vec![(index, raw.value_of(&spec, 0))]);
        let status = self.status.get();
        let tag = status.tags.as_ref().and_then(|t| t.get(&spec.name)).cloned();
        tag.map(|status| Tag { name: spec.name.clone(), status })
            .ok_or(WriteError::UnknownTag(spec.name.clone()))
    }

    /// Writes bits, keeping the contact bookkeeping.
    async fn write_bits(&mut self, at: &Address, values: &[bool]) -> Result<(), WriteError> {
        let result = self.plc.write_bits(at, values).await;
        self.contact(&result);
        result.map_err(WriteError::Plc)
    }

    /// Writes words, keeping the contact bookkeeping.
    async fn write_words(&mut self, at: &Address, values: &[u16]) -> Result<(), WriteError> {
        let result = self.plc.write_words(at, values).await;
        self.contact(&result);
        result.map_err(WriteError::Plc)
    }
}
