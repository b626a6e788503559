//! [`PlcMemory`] for the MEWTOCOL client: DT words with RD/WD, contact words (WX, WY, WR,
//! WL) with RCC/WCC, contacts with RCS/RCP/RCC and WCS/WCP, split at the frame size.
//!
//! Bit reads: one contact with RCS, up to 8 with RCP, more with RCC over the words that hold
//! them. Bit writes: one with WCS, more with WCP, 8 at a time. Chunks go out in address
//! order; if one fails the call fails and earlier chunks stay written.

use async_trait::async_trait;

use super::address::{self, Target};
use super::client::MewtocolClient;
use super::command::{Contact, ContactArea, MAX_CONTACTS, Request, Response};
use crate::protocols::{Address, PlcError, PlcMemory};

fn unexpected() -> PlcError {
    PlcError::Malformed("reply of the wrong kind")
}

fn contact(area: ContactArea, n: u32) -> Contact {
    Contact { area, word: (n / 16) as u16, bit: (n % 16) as u8 }
}

impl MewtocolClient {
    async fn words(&self, request: Request) -> Result<Vec<u16>, PlcError> {
        match self.call(&request).await? {
            Response::Words(w) => Ok(w),
            _ => Err(unexpected()),
        }
    }
}

#[async_trait]
impl PlcMemory for MewtocolClient {
    fn link_stats(&self) -> crate::protocols::transport::LinkStats {
        self.link_stats()
    }

    fn recorder(&self) -> Option<std::sync::Arc<crate::capture::Recorder>> {
        self.recorder()
    }

    fn parse_address(&self, text: &str) -> Result<Address, PlcError> {
        address::parse(text)
    }

    async fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let target = address::resolve(start, count as usize)?;
        let mut out = Vec::with_capacity(count as usize);
        let max = self.config().max_read_words() as u32;
        let mut done = 0u32;
        while done < count as u32 {
            let n = (count as u32 - done).min(max);
            let request = match target {
                Target::Data(first) => Request::ReadData { start: first + done, end: first + done + n - 1 },
                Target::Words(area, first) => {
                    let s = first + done as u16;
                    Request::ReadContactWords { area, start: s, end: s + n as u16 - 1 }
                }
                Target::Bits(..) => return Err(PlcError::OutOfRange("contacts are read with read_bits")),
            };
            out.extend(self.words(request).await?);
            done += n;
        }
        Ok(out)
    }

    async fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        let target = address::resolve(start, values.len())?;
        for (i, chunk) in values.chunks(self.config().max_write_words()).enumerate() {
            let offset = (i * self.config().max_write_words()) as u32;
            let request = match target {
                Target::Data(first) => Request::WriteData { start: first + offset, values: chunk.to_vec() },
                Target::Words(area, first) => {
                    Request::WriteContactWords { area, start: first + offset as u16, values: chunk.to_vec() }
                }
                Target::Bits(..) => return Err(PlcError::OutOfRange("contacts are written with write_bits")),
            };
            self.call(&request).await?;
        }
        Ok(())
    }

    async fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        let Target::Bits(area, first) = address::resolve(start, count as usize)? else {
            return Err(PlcError::OutOfRange("words are read with read_words"));
        };
        match count {
            0 => Ok(Vec::new()),
            1 => match self.call(&Request::ReadContact(contact(area, first))).await? {
                Response::Contact(v) => Ok(vec![v]),
                _ => Err(unexpected()),
            },
            n if n as usize <= MAX_CONTACTS => {
                let contacts = (first..first + n as u32).map(|i| contact(area, i)).collect();
                match self.call(&Request::ReadContacts(contacts)).await? {
                    Response::Contacts(v) => Ok(v),
                    _ => Err(unexpected()),
                }
            }
            n => {
                let (w0, w1) = (first / 16, (first + n as u32 - 1) / 16);
                let max = self.config().max_read_words() as u32;
                let mut words = Vec::new();
                let mut w = w0;
                while w <= w1 {
                    let end = (w + max - 1).min(w1);
                    let request = Request::ReadContactWords { area, start: w as u16, end: end as u16 };
                    words.extend(self.words(request).await?);
                    w = end + 1;
                }
                Ok((first..first + n as u32)
                    .map(|i| words[(i / 16 - w0) as usize] & (1 << (i % 16)) != 0)
                    .collect())
            }
        }
    }

    async fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        let Target::Bits(area, first) = address::resolve(start, values.len())? else {
            return Err(PlcError::OutOfRange("words are written with write_words"));
        };
        if let [value] = values {
            self.call(&Request::WriteContact(contact(area, first), *value)).await?;
            return Ok(());
        }
        for (i, chunk) in values.chunks(MAX_CONTACTS).enumerate() {
            let base = first + (i * MAX_CONTACTS) as u32;
            let items = chunk.iter().enumerate().map(|(j, &v)| (contact(area, base + j as u32), v)).collect();
            self.call(&Request::WriteContacts(items)).await?;
        }
        Ok(())
    }
}
