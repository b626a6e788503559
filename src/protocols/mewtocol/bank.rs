//! The memory a simulated Panasonic PLC serves: DT registers and contact words of X, Y, R,
//! L, T and C, shared with whoever simulates the machine.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use super::command::{Contact, ContactArea, Request, Response};
use super::error_code::DATA_ERROR;

/// A bank shared between the server and the simulation (never lock it across an `.await`).
pub type SharedBank = Arc<Mutex<Bank>>;

/// Data registers and contact words.
#[derive(Clone, Debug)]
pub struct Bank {
    dt: Vec<u16>,
    contacts: BTreeMap<ContactArea, Vec<u16>>,
}

impl Default for Bank {
    /// 32765 DT registers (an FP-X's size) and 512 words per contact area.
    fn default() -> Self {
        Bank::with_sizes(32_765, 512)
    }
}

impl Bank {
    /// A zeroed bank with `dt` data registers and `words` words per contact area.
    pub fn with_sizes(dt: usize, words: usize) -> Bank {
        let contacts = ContactArea::ALL.into_iter().map(|a| (a, vec![0; words])).collect();
        Bank { dt: vec![0; dt], contacts }
    }

    /// This bank wrapped for sharing.
    pub fn shared(self) -> SharedBank {
        Arc::new(Mutex::new(self))
    }

    /// Data register `n`, if it exists.
    pub fn dt(&self, n: usize) -> Option<u16> {
        self.dt.get(n).copied()
    }

    /// Sets data register `n` (ignored past the end).
    pub fn set_dt(&mut self, n: usize, value: u16) {
        if let Some(w) = self.dt.get_mut(n) {
            *w = value;
        }
    }

    /// Contact word `n` of an area, if it exists.
    pub fn word(&self, area: ContactArea, n: usize) -> Option<u16> {
        self.contacts.get(&area)?.get(n).copied()
    }

    /// Sets contact word `n` of an area (ignored past the end).
    pub fn set_word(&mut self, area: ContactArea, n: usize, value: u16) {
        if let Some(w) = self.contacts.get_mut(&area).and_then(|v| v.get_mut(n)) {
            *w = value;
        }
    }

    /// Contact `word * 16 + bit` of an area.
    pub fn bit(&self, area: ContactArea, n: usize) -> Option<bool> {
        self.word(area, n / 16).map(|w| w & (1 << (n % 16)) != 0)
    }

    fn contact(&self, c: &Contact) -> Result<bool, u8> {
        self.bit(c.area, c.word as usize * 16 + c.bit as usize).ok_or(DATA_ERROR)
    }

    fn set_contact(&mut self, c: &Contact, v: bool) -> Result<(), u8> {
        let w = self.contacts.get_mut(&c.area).and_then(|w| w.get_mut(c.word as usize)).ok_or(DATA_ERROR)?;
        if v {
            *w |= 1 << c.bit;
        } else {
            *w &= !(1 << c.bit);
        }
        Ok(())
    }

    fn range(len: usize, start: usize, count: usize) -> Result<std::ops::Range<usize>, u8> {
        if start + count > len { Err(DATA_ERROR) } else { Ok(start..start + count) }
    }

    /// Executes a command as the PLC would; the error is the MEWTOCOL code to answer.
    /// Nothing is written unless the whole command is in range.
    pub fn execute(&mut self, request: &Request) -> Result<Response, u8> {
        match request {
            Request::ReadContact(c) => self.contact(c).map(Response::Contact),
            Request::ReadContacts(cs) => {
                cs.iter().map(|c| self.contact(c)).collect::<Result<_, _>>().map(Response::Contacts)
            }
            Request::ReadContactWords { area, start, end } => {
                let words = self.contacts.get(area).ok_or(DATA_ERROR)?;
                let r = Self::range(words.len(), *start as usize, (end - start) as usize + 1)?;
                Ok(Response::Words(words[r].to_vec()))
            }
            Request::WriteContact(c, v) => self.set_contact(c, *v).map(|_| Response::Written),
            Request::WriteContacts(items) => {
                for (c, _) in items {
                    self.contact(c)?;
                }
                for (c, v) in items {
                    self.set_contact(c, *v)?;
                }
                Ok(Response::Written)
            }
            Request::WriteContactWords { area, start, values } => {
                let words = self.contacts.get_mut(area).ok_or(DATA_ERROR)?;
                let r = Self::range(words.len(), *start as usize, values.len())?;
                words[r].copy_from_slice(values);
                Ok(Response::Written)
            }
            Request::ReadData { start, end } => {
                let r = Self::range(self.dt.len(), *start as usize, (end - start) as usize + 1)?;
                Ok(Response::Words(self.dt[r].to_vec()))
            }
            Request::WriteData { start, values } => {
                let r = Self::range(self.dt.len(), *start as usize, values.len())?;
                self.dt[r].copy_from_slice(values);
                Ok(Response::Written)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn executes_and_refuses_out_of_range() {
        let mut bank = Bank::with_sizes(10, 4);
        let y = |word, bit| Contact { area: ContactArea::Y, word, bit };
        bank.execute(&Request::WriteContactWords { area: ContactArea::Y, start: 0, values: vec![0x0700] })
            .unwrap();
        assert_eq!(bank.execute(&Request::ReadContact(y(0, 8))), Ok(Response::Contact(true)));
        assert_eq!(bank.execute(&Request::ReadContact(y(0, 7))), Ok(Response::Contact(false)));
        assert_eq!(bank.execute(&Request::ReadContact(y(4, 0))), Err(DATA_ERROR));
        assert_eq!(
            bank.execute(&Request::WriteContacts(vec![(y(0, 0), true), (y(9, 0), true)])),
            Err(DATA_ERROR)
        );
        assert_eq!(bank.word(ContactArea::Y, 0), Some(0x0700));
        assert_eq!(bank.execute(&Request::WriteData { start: 9, values: vec![1, 2] }), Err(DATA_ERROR));
        bank.execute(&Request::WriteData { start: 8, values: vec![1, 2] }).unwrap();
        assert_eq!(bank.execute(&Request::ReadData { start: 8, end: 9 }), Ok(Response::Words(vec![1, 2])));
        assert_eq!(bank.execute(&Request::ReadData { start: 8, end: 10 }), Err(DATA_ERROR));
    }
}
